"""Every number of a campaign report, computed from the result records alone.

Records are grouped by (planner, attack) over all scenes, and by (family, planner, attack); a
family is highway-env's (highway, intersection, ...) or a recorded one's (us101, ...).
Rates carry Wilson intervals, means percentile-bootstrap intervals (riskmap.infra.stats):

    failures that count      valid, avoidable, at-fault collisions / finished jobs (the report's
                             headline; riskmap.sim.records.failures): the ego's front hit the other, a
                             driver reacting 0.5 s after the threat became visible could have
                             avoided it, and (attacks) the adversary did it alone within
                             physical limits. failure_classes counts each class over the
                             collisions; a record without the classification is "unknown"
    collision rate           ego collisions / finished jobs
    adversary collision      collisions with the attack's adversary / jobs whose attack had one
    adversary off-road       adversary off the road before any collision / jobs with an adversary
    other off-road           another vehicle near the ego off the road before a collision / jobs
    kinematic value (m/s)    mean |v_ego - v_partner| over collisions
    solution rate            collisions the ego alone could have avoided / collisions
    Safety %                 mean (and 90th percentile) over jobs of the per-episode Safety %
                             (jobs that do not measure it, e.g. the crash attack's, are left out)
    distance (m)             mean distance driven
    guard                    for a guarded planner (guard:SPEC): decision frames, interventions and
                             hard brakes summed over the jobs whose record holds them, and the
                             intervention ratio interventions / frames (None: no such job)

The CRASH ablation (attacks of category "selection") has one row per (attack label, planner), as
CRASH's Table III: its collision rate is collisions with the adversary over every finished job,
scenes that could not be attacked included (`not_attacked` counts them).

Timings (plan ms, wall s) depend on the machine; they sit apart under "timing".

Every row that names a planner holds its SPEC ("planner") and its display name ("planner_name",
riskmap.registry.display_names over the campaign's planners), which tables and figures show.
"""

from __future__ import annotations

from collections import Counter, defaultdict

import numpy as np

from adversary.attacks.episode import GUARD_FIELDS
from adversary.attacks.recorded import job_family
from riskmap.infra.stats import bootstrap_mean, wilson
from riskmap.registry import display_name, display_names, split_name
from riskmap.sim.records.failures import summarise_failures
from riskmap.sim.records.metrics import CAMPAIGN_COLLISION_TYPES
from riskmap.sim.records.record import current_names

COLLISION_TYPES = CAMPAIGN_COLLISION_TYPES      # the labels a campaign record's collision_type can hold


def _group_metrics(records: list[dict]) -> dict:
    ok = [r for r in records if r["status"] == "ok"]
    adv = [r for r in ok if r.get("has_adversary")]
    collided = [r for r in ok if r["collided"]]
    solved = [r for r in collided if r.get("solution_found") is not None]
    classes = summarise_failures([r.get("failure") for r in collided], len(ok))
    return {
        "jobs": len(records), "failed": len(records) - len(ok),
        "failure_rate": wilson(classes["counted"], len(ok)),
        "failure_classes": classes,
        "collision_rate": wilson(len(collided), len(ok)),
        "adversary_collision_rate": wilson(sum(r["collided_with_adversary"] for r in adv), len(adv)),
        "adversary_off_road": wilson(sum(bool(r["adversary_off_road"]) for r in adv), len(adv)),
        "other_off_road": wilson(sum(bool(r["other_off_road"]) for r in ok), len(ok)),
        "kinematic_mps": bootstrap_mean([r["kinematic_mps"] for r in collided]),
        "solution_rate": wilson(sum(bool(r["solution_found"]) for r in solved), len(solved)),
        "safety_pct": bootstrap_mean([r["safety_pct"] for r in ok]),
        "distance_m": bootstrap_mean([r["distance_m"] for r in ok]),
        "guard": _guard_metrics(ok),
    }


def _guard_metrics(ok: list[dict]) -> dict | None:
    """What the guard did over finished jobs (module docstring); records written before the
    guard's counts were kept, and unguarded planners' (None), are left out."""
    counted = [r for r in ok if all(r.get(k) is not None for k in GUARD_FIELDS)]
    if not counted:
        return None
    frames, interventions, hard = (sum(int(r[k]) for r in counted) for k in GUARD_FIELDS)
    return {"jobs": len(counted), "frames": frames, "interventions": interventions, "hard": hard,
            "intervention_ratio": interventions / frames if frames else None}


def _ablation_metrics(records: list[dict]) -> dict:
    """The CRASH ablation's numbers of one (attack, planner) group (module docstring)."""
    ok = [r for r in records if r["status"] == "ok"]
    attacked = [r for r in ok if r.get("attacked", True)]
    hits = [r for r in ok if r["collided_with_adversary"]]
    solved = [r for r in hits if r.get("solution_found") is not None]
    return {
        "jobs": len(records), "failed": len(records) - len(ok), "not_attacked": len(ok) - len(attacked),
        "adversary_collision_rate": wilson(len(hits), len(ok)),
        "collision_rate": wilson(sum(bool(r["collided"]) for r in ok), len(ok)),
        "adversary_off_road": wilson(sum(bool(r["adversary_off_road"]) for r in attacked), len(attacked)),
        "other_off_road": wilson(sum(bool(r["other_off_road"]) for r in attacked), len(attacked)),
        "kinematic_mps": bootstrap_mean([r["kinematic_mps"] for r in hits]),
        "solution_rate": wilson(sum(bool(r["solution_found"]) for r in solved), len(solved)),
    }


def _ablation(records: list[dict]) -> tuple[list[dict], list[dict]] | tuple[None, None]:
    """(rows, timing rows) of the CRASH ablation, in the same (attack, planner) order."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        groups[r["attack"], r["planner"]].append(r)
    if not groups:
        return None, None
    keys = sorted(groups)
    return ([{"attack": a, "planner": p, **_ablation_metrics(groups[a, p])} for a, p in keys],
            [{"attack": a, "planner": p, **_timing(groups[a, p])} for a, p in keys])


def _timing(records: list[dict]) -> dict:
    plan = [r["timing"].get("plan_ms_median") for r in records
            if r.get("timing", {}).get("plan_ms_median") is not None]
    wall = [r["timing"]["wall_s"] for r in records if "wall_s" in r.get("timing", {})]
    return {"plan_ms_median": float(np.median(plan)) if plan else None,
            "job_wall_s_median": float(np.median(wall)) if wall else None,
            "job_wall_s_total": float(np.sum(wall)) if wall else None}


def _rows(records: list[dict], keys: tuple[str, ...]) -> tuple[list[dict], list[dict]]:
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        groups[tuple(r[k] for k in keys)].append(r)
    rows, timing = [], []
    for key in sorted(groups):
        rows.append({**dict(zip(keys, key)), **_group_metrics(groups[key])})
        timing.append({**dict(zip(keys, key)), **_timing(groups[key])})
    return rows, timing


def _collision_types(records: list[dict]) -> list[dict]:
    counts: dict[tuple, Counter] = defaultdict(Counter)
    for r in records:
        if r["status"] == "ok":
            # a crash attack's collision with a vehicle other than its adversary has no type
            counts[r["planner"], r["attack"]].update([r["collision_type"]] if r["collided"]
                                                     and r["collision_type"] else [])
    return [{"planner": p, "attack": a, **{t: counts[p, a][t] for t in COLLISION_TYPES},
             "total": sum(counts[p, a].values())} for p, a in sorted(counts)]


GUARD_PAIR_METRICS = ("failure_rate", "collision_rate", "safety_pct", "distance_m")


def _scene_of(record: dict) -> tuple:
    """The scene a job drove: family env, seed and episode (and, recorded, its file and vehicle)."""
    return (record["env_id"], record["scene_seed"], record["episode"], record.get("recording"),
            record.get("ego_id"))


def _unguarded(planner: str, planners) -> str | None:
    """The SPEC among `planners` that `guard:SPEC` (or `guarded:SPEC`) wraps, or None."""
    prefix, _, inner = planner.partition(":")
    if prefix not in ("guard", "guarded"):
        return None
    # the inner SPEC as listed, whatever its own name= (the planner is the same)
    bare = {split_name(p)[0]: p for p in planners}
    return inner if inner in planners else bare.get(split_name(inner)[0])


def _guard_pairs(records: list[dict], names: dict[str, str]) -> list[dict]:
    """`guard:SPEC` (or `guarded:SPEC`) next to the same attack on SPEC over the scenes both drove
    (SPEC's other scenes are left out, e.g. a family the guarded planner was not listed on): the
    metrics off and on, what the guard did (`_guard_metrics`), `identical` (every metric off
    equals on, intervals included) and, when identical, `note`: the sentence that says whether
    the guard acted at all."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        groups[r["planner"], r["attack"]].append(r)
    pairs = []
    planners = {r["planner"] for r in records}
    for (planner, attack), guarded in sorted(groups.items()):
        inner = _unguarded(planner, planners)
        if inner is None or (inner, attack) not in groups:
            continue
        scenes = {_scene_of(r) for r in guarded}
        base = [r for r in groups[inner, attack] if _scene_of(r) in scenes]
        if not base:
            continue
        off_row, on_row = _group_metrics(base), _group_metrics(guarded)
        off = {k: off_row[k] for k in GUARD_PAIR_METRICS}
        on = {k: on_row[k] for k in GUARD_PAIR_METRICS}
        pair = {"planner": inner, "planner_name": names[inner], "attack": attack, "off": off, "on": on,
                "guard": on_row["guard"], "identical": off == on}
        pair["note"] = _guard_note(pair) if pair["identical"] else None
        pairs.append(pair)
    return pairs


def _guard_note(pair: dict) -> str:
    """The sentence under the guard table for a pair whose metrics are identical off and on."""
    where = f"{planner_name(pair)}, {pair['attack']}: guard on and off give identical results"
    guard = pair["guard"]
    if guard is None:
        return f"{where}; the records hold no guard counts (written before they were kept)."
    if guard["interventions"] == 0:
        if guard["frames"] == 0:
            return f"{where}; the guard never intervened (it made no decision: 0 frames)."
        return f"{where}; the guard never intervened (0 of {guard['frames']} frames)."
    times = "time" if guard["interventions"] == 1 else "times"
    brakes = "hard brake" if guard["hard"] == 1 else "hard brakes"
    return (f"{where}; the guard intervened {guard['interventions']} {times} without changing the "
            f"outcome ({guard['interventions']} of {guard['frames']} frames, {guard['hard']} {brakes}).")


def _search_history(records: list[dict]) -> list[dict]:
    """Per-generation collisions and Pareto fronts that search attacks put in attack_extra."""
    out = []
    for r in records:
        extra = r.get("attack_extra") or {}
        if r["status"] == "ok" and r["attack_category"] == "search" and (
                extra.get("generations") or extra.get("pareto_front")):
            out.append({"job_id": r["job_id"], "planner": r["planner"], "attack": r["attack"],
                        "generations": extra.get("generations") or [],
                        "pareto_front": extra.get("pareto_front") or [],
                        "objective_names": extra.get("objective_names") or []})
    return out


def worst_scenes(records: list[dict], count: int) -> list[dict]:
    """The `count` worst finished jobs: collisions first (with the adversary, then faster), then
    the most dangerous Safety %; ties by job id."""
    ok = [r for r in records if r["status"] == "ok"]
    ok.sort(key=lambda r: (not r["collided"], not r["collided_with_adversary"],
                           -(r["kinematic_mps"] or 0.0), -(r["safety_pct"] or 0.0), r["job_id"]))
    return ok[:count]


def planner_name(row: dict) -> str:
    """The planner of a row or record as tables and figures show it: the display name
    `report_numbers` put beside its SPEC, else the one its SPEC alone makes."""
    return row.get("planner_name") or display_name(row["planner"])


def _name_rows(rows, names: dict[str, str]) -> None:
    """Put each row's display name beside its SPEC (rows: a list of dicts, or None)."""
    for row in rows or ():
        if "planner" in row:
            row["planner_name"] = names[row["planner"]]


def report_numbers(records: list[dict], gallery: int,
                   names: dict[str, str] | None = None) -> tuple[dict, dict]:
    """(results, timing): everything the page shows; timing is machine-dependent. Records of
    older campaigns are read under today's names (riskmap.sim.records.record.current_names). `names`:
    SPEC -> display name (default: `display_names` of the records' planners)."""
    records = [current_names(r) for r in records]
    names = names or display_names(sorted({r["planner"] for r in records}))
    for r in records:
        r.setdefault("family", job_family(r["env_id"]))
    comparison, timing_rows = _rows(records, ("planner", "attack"))
    by_family, _ = _rows(records, ("family", "planner", "attack"))
    selection = [r for r in records if r["attack_category"] == "selection"]
    search = [r for r in records if r["attack_category"] == "search"]
    ablation, ablation_timing = _ablation(selection)
    results = {
        "jobs": len(records),
        "failed": sum(r["status"] != "ok" for r in records),
        "comparison": comparison,
        "by_family": by_family,
        "collision_types": _collision_types(records),
        "crash_ablation": ablation,
        "search": _rows(search, ("attack", "planner"))[0] if search else None,
        "search_history": _search_history(records),
        "guard": _guard_pairs(records, names) or None,
        "worst": [{**{k: r[k] for k in ("job_id", "planner", "env_id", "scene_seed", "episode", "attack",
                                        "collided", "collided_with_adversary", "collision_type",
                                        "kinematic_mps", "safety_pct", "distance_m")},
                   # a recorded family's scene: its recording and vehicle
                   **{k: r[k] for k in ("recording", "ego_id") if k in r}}
                  for r in worst_scenes(records, gallery)],
        "failures": [{"job_id": r["job_id"], "error": r["error"]}
                     for r in records if r["status"] != "ok"],
    }
    for key in ("comparison", "by_family", "collision_types", "crash_ablation", "search", "search_history",
                "guard", "worst"):
        _name_rows(results[key], names)
    _name_rows(timing_rows, names)
    _name_rows(ablation_timing, names)
    return results, {"by_planner_attack": timing_rows, "crash_ablation": ablation_timing, **_timing(records)}
