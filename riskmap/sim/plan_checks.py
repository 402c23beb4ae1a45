"""The planner contract's sanity checks on one plan, and their count over an episode and a run.

`plan_problems` says what is wrong with a plan: not a `Plan`, wrong shape, NaN/inf, km/h instead
of m/s, world instead of ego coordinates, impossible speeds, swapped or backward axes. The
rollout (`riskmap.sim.rollout`) runs it on every plan a planner makes and counts the failures in
`ImplausiblePlans`; `riskmap check-planner` names them one line each. A check is a few numpy
operations on 12 points (microseconds), against a replan period of 500 ms.

An implausible plan is still driven as made (the loop's tracking controller follows it): the
count says a run's numbers came from plans that break the contract, without changing the numbers
of any planner that keeps it. Wrong shape or non-finite waypoints cannot be tracked at all and
stop the episode (`riskmap.sim.plan.check_plan`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from riskmap.sim.plan import PLAN_DT_S, PLAN_STEPS, Plan

MAX_SPEED_MS = 60.0          # faster than any road vehicle here: the waypoints are not metres
MAX_ACCEL_MS2 = 10.0         # beyond hard braking: the first waypoint does not start at the ego
KMH_PER_MS = 3.6


def plan_problems(plan, speed: float) -> list[str]:
    """What is wrong with `plan` made at ego speed `speed` (m/s); empty if nothing."""
    if not isinstance(plan, Plan):
        return [f"plan() returned a {type(plan).__name__}, not a riskmap.sim.plan.Plan"]
    try:
        waypoints = np.asarray(plan.waypoints, dtype=np.float64)
    except (TypeError, ValueError):
        return ["Plan.waypoints is not numeric; give a float array [12, 2]"]
    if waypoints.shape != (PLAN_STEPS, 2):
        return [f"Plan.waypoints has shape {waypoints.shape}; the contract is [12, 2] (6 s at 0.5 s)"]
    if not np.isfinite(waypoints).all():
        return ["Plan.waypoints holds NaN or inf; every waypoint must be finite"]
    return _scale_problems(waypoints, speed) + _axis_problems(waypoints, speed)


def _reach_m(speed: float) -> float:
    """How far the first waypoint (0.5 s ahead) can be from the ego at `speed` (m/s)."""
    return speed * PLAN_DT_S + 0.5 * MAX_ACCEL_MS2 * PLAN_DT_S ** 2 + 1.0


def _scale_problems(waypoints: np.ndarray, speed: float) -> list[str]:
    """Units and frame: km/h, world coordinates, impossible speeds (the first that applies)."""
    steps = np.linalg.norm(np.diff(np.vstack([[0.0, 0.0], waypoints]), axis=0), axis=1) / PLAN_DT_S
    first = float(np.linalg.norm(waypoints[0]))
    if speed > 3.0 and abs(steps[0] / speed - KMH_PER_MS) < 0.4:
        return [(f"the first step implies {steps[0]:.1f} m/s at a speed of {speed:.1f} m/s "
                "(3.6x: km/h?); the waypoints are metres 0.5 s apart")]
    if first > _reach_m(speed):
        return [(f"the first waypoint is {first:.0f} m from the ego at {speed:.1f} m/s; "
                "waypoints are in the ego frame (origin at the ego, x forward, y left), "
                "not world coordinates")]
    if steps.max() > MAX_SPEED_MS:
        return [f"the waypoints imply {steps.max():.0f} m/s; they are metres 0.5 s apart"]
    return []


def _axis_problems(waypoints: np.ndarray, speed: float) -> list[str]:
    """In one second at speed no vehicle turns by more than about 60 degrees: the plan's first
    second must point forward (x), else its axes are not the ego frame's."""
    second = waypoints[round(1.0 / PLAN_DT_S) - 1]
    if speed <= 3.0 or np.linalg.norm(waypoints[0]) > _reach_m(speed) \
            or np.linalg.norm(second) <= 0.5 * speed:
        return []
    angle = np.degrees(abs(np.arctan2(second[1], second[0])))
    if angle > 120:
        return ["the plan runs backwards at speed; x points forward in the ego frame"]
    if angle > 60:
        return ["the plan runs sideways at speed; x is forward and y left (swapped axes?)"]
    return []


# The record fields of the count (`riskmap.sim.record.EpisodeRecord`).
COUNT_FIELD, FIRST_FIELD = "implausible_plans", "implausible_plan_first"


@dataclass
class ImplausiblePlans:
    """The plans of one episode (or several drives) that fail `plan_problems`: how many, and the
    first one's problems with the time of the scene it was made from."""

    count: int = 0
    first: str | None = None

    def check(self, plan: Plan, scene) -> None:
        """Count `plan` if it fails a check at the ego speed of `scene`, the scene it was made
        from (what the planner saw)."""
        problems = plan_problems(plan, float(scene.ego_state()[4]))
        if problems:
            self.add(1, f"at {scene.time_s:.1f} s: " + "; ".join(problems))

    def add(self, count: int, first: str | None) -> None:
        self.count += int(count)
        if self.first is None:
            self.first = first

    def add_record(self, record: dict) -> None:
        """Add the count of an episode record (a dict with `fields()`' keys)."""
        self.add(record.get(COUNT_FIELD) or 0, record.get(FIRST_FIELD))

    def fields(self) -> dict:
        return {COUNT_FIELD: self.count, FIRST_FIELD: self.first}


def summarise_implausible(records: list[dict], where: Callable[[dict], str]) -> dict:
    """Over a run's episode records: implausible plans in all (None when a record predates the
    count), episodes with any, and the first message, prefixed by `where(record)`."""
    counts = [r.get(COUNT_FIELD) for r in records]
    flagged = [r for r in records if r.get(COUNT_FIELD)]
    return {COUNT_FIELD: None if any(c is None for c in counts) else int(sum(counts)),
            "implausible_plan_episodes": len(flagged),
            FIRST_FIELD: f"{where(flagged[0])} {flagged[0][FIRST_FIELD]}" if flagged else None}


def implausible_note(rows: dict, unit: str = "episodes") -> str:
    """The line under a results table naming each planner with implausible plans ({name:
    (summary, episodes)}, summaries of `summarise_implausible`); "" when every count is 0. A line,
    not a column: the count is 0 for every planner that keeps the contract."""
    parts = [f"{name}: {s[COUNT_FIELD]} plans in {s['implausible_plan_episodes']} of {n} {unit}, first "
             f"{s[FIRST_FIELD]}" for name, (s, n) in rows.items() if s.get(COUNT_FIELD)]
    if not parts:
        return ""
    return ("Implausible plans (they break the planner contract's checks, README \"The planner "
            "contract\"; they were driven as made): " + " | ".join(parts) + "\n")
