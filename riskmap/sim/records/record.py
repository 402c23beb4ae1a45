"""The one per-episode record that every closed-loop command writes (`riskmap drive`, `evaluate`,
the CommonRoad replay, stress-test jobs, CRASH attacks).

`EpisodeRecord` holds the measurements every command shares, under one name each and with units
in the names; whatever a command measures beyond them goes to `extra` and is written flat beside
them (`as_dict`). `min_gap_m` is None, never inf, when no other vehicle came within the gap radius,
so that the record is plain JSON.

Records written before these names were fixed (campaign stores, attack results, evaluation
episodes on disk) are read through `current_names`, the one place that knows the old names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

# Old record key -> its name now. `ego_progress_m`/`ego_off_road` were the CRASH judge's,
# `progress_m`/`ego_off_road` the campaign job record's and `progress_m` Table I's.
OLD_NAMES = {"progress_m": "distance_m", "ego_progress_m": "distance_m", "ego_off_road": "off_road"}


@dataclass(frozen=True)
class EpisodeRecord:
    """One driven episode. A measurement a command does not take is None."""

    planner: str                        # the planner SPEC or class name the command names it by
    collided: bool
    off_road: bool
    simulated_s: float | None
    distance_m: float | None            # path length the ego drove
    mean_speed_mps: float | None
    min_gap_m: float | None             # None: no other vehicle came within the gap radius
    plan_calls: int | None
    plan_ms_median: float | None        # the plan_ms_* are None when the planner never planned
    plan_ms_mean: float | None
    plan_ms_p90: float | None
    # Times the ego's front crossed the stop line of a lane it was on while the light governing
    # its turn was red (amber counts as red); once per crossing. 0 where there are no signals.
    red_light_violations: int = 0
    # Times the ego waited (speed < 0.5 m/s for >= 1 s) while a crossing vehicle passed ahead of it.
    yield_events: int = 0
    # Plans that failed the planner contract's checks (`riskmap.sim.loop.plan_checks`; driven as made)
    # and the first one's problems with the time it was made. 0 and None where nothing planned.
    implausible_plans: int = 0
    implausible_plan_first: str | None = None
    # Replans at which the planner had no plan (`riskmap.sim.loop.plan.NoSolution`, or an adapted
    # planner's empty trajectory; the ego braked) and the first one's time and reason.
    no_solution_plans: int = 0
    no_solution_first: str | None = None
    extra: dict = field(default_factory=dict)   # command-specific fields, written flat

    def as_dict(self) -> dict:
        """One flat JSON-ready dict: the core fields, then the extras."""
        core = {name: getattr(self, name) for name in CORE_FIELDS}
        clash = sorted(set(core) & set(self.extra))
        if clash:
            raise ValueError(f"extra fields {clash} reuse core names of EpisodeRecord")
        core["min_gap_m"] = finite_or_none(core["min_gap_m"])
        return {**core, **self.extra}

    @classmethod
    def from_dict(cls, record: dict) -> EpisodeRecord:
        """The record of a dict `as_dict` wrote, or an older one (`current_names`)."""
        record = current_names(record)
        core = {name: record.get(name, COUNT_DEFAULTS.get(name)) for name in CORE_FIELDS}
        return cls(**core, extra={k: v for k, v in record.items() if k not in core})

    @classmethod
    def measured(cls, planner: str, collided: bool, off_road: bool, simulated_s: float,
                 distance_m: float, speeds: list[float], gaps: list[float],
                 plan_times_s: list[float], extra: dict | None = None,
                 red_light_violations: int = 0, yield_events: int = 0, implausible_plans: int = 0,
                 implausible_plan_first: str | None = None, no_solution_plans: int = 0,
                 no_solution_first: str | None = None) -> EpisodeRecord:
        """The record from a loop's per-step speeds (m/s), gaps (m) and plan times (s). A count
        (`red_light_violations`, `yield_events`, `implausible_plans`, `no_solution_plans`) may also
        come in `extra`; it moves to its field."""
        extra = dict(extra or {})
        counts = {"red_light_violations": red_light_violations, "yield_events": yield_events,
                  "implausible_plans": implausible_plans, "no_solution_plans": no_solution_plans}
        for name in COUNT_DEFAULTS:
            if name in extra:
                value = extra.pop(name)
                if counts[name] not in (0, value):
                    raise ValueError(f"{name} given twice: {counts[name]!r} and extra {value!r}")
                counts[name] = value
        return cls(planner=planner, collided=bool(collided), off_road=bool(off_road),
                   simulated_s=simulated_s, distance_m=distance_m,
                   mean_speed_mps=float(np.mean(speeds)) if speeds else 0.0,
                   min_gap_m=finite_or_none(min(gaps)) if gaps else None,
                   plan_calls=len(plan_times_s), **plan_ms_stats(plan_times_s),
                   **{name: int(value) for name, value in counts.items()},
                   implausible_plan_first=implausible_plan_first, no_solution_first=no_solution_first,
                   extra=extra)


CORE_FIELDS = tuple(f.name for f in fields(EpisodeRecord) if f.name != "extra")
# Counts that records written before they existed did not hold: read as their default (0).
COUNT_DEFAULTS = {"red_light_violations": 0, "yield_events": 0, "implausible_plans": 0,
                  "no_solution_plans": 0}


def finite_or_none(value: float | None) -> float | None:
    """A gap of inf (nobody near) as None; JSON has no inf."""
    return None if value is None or not math.isfinite(value) else float(value)


def plan_ms_stats(plan_times_s: list[float]) -> dict:
    """Median, mean and 90th percentile of the plan times in ms (None without plans)."""
    if not plan_times_s:
        return {"plan_ms_median": None, "plan_ms_mean": None, "plan_ms_p90": None}
    return {"plan_ms_median": 1000 * float(np.median(plan_times_s)),
            "plan_ms_mean": 1000 * float(np.mean(plan_times_s)),
            "plan_ms_p90": 1000 * float(np.percentile(plan_times_s, 90))}


def current_names(record: dict) -> dict:
    """A copy of a stored record (or CRASH judge metrics) under today's names: the old names of
    `OLD_NAMES` renamed and a `min_gap_m` of inf as None. Other keys, and records without these
    fields (a failed job's), pass unchanged. Raises ValueError when an old and a new name hold
    different values."""
    out = dict(record)
    for old, new in OLD_NAMES.items():
        if old not in out:
            continue
        value = out.pop(old)
        if new in out and out[new] != value:
            raise ValueError(f"record holds both {old}={value!r} and {new}={out[new]!r}")
        out[new] = value
    if "min_gap_m" in out:
        out["min_gap_m"] = finite_or_none(out["min_gap_m"])
    return out
