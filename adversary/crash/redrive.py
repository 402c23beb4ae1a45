"""One attack record driven again: the generated trajectories of an `adversary attack` record
(OUT/attacks/<scene>.json) replayed against a planner (`judge.rollout`, the closed loop the attack
was judged in) and judged (`judge.judge`), with the ego's progress and, for a guarded planner,
the guard's decisions. The adversary does not react: the tracks are the ones the attack stored."""

from __future__ import annotations

import numpy as np

from adversary.crash.judge import judge, rollout
from riskmap.sim.loop.plan import traits_of

GUARD_SUMMARY_KEYS = ("frames", "interventions", "intervention_ratio", "single", "sustained", "hard")


def redrive_attack(record, attack: dict, planner, spec: str) -> dict:
    """One rollout of `attack`'s tracks on `record` (its scene, `scenes.load_record`) with
    `planner` (made from `spec`) driving the ego: collision with the adversary and with anyone,
    progress over the attack horizon (path length from t0; the rollout ignores contact, so the
    whole horizon is driven), min gap, and the guard's summary where the planner has a guard."""
    tracks = np.asarray(attack["tracks"], dtype=np.float64)
    rows = attack["metrics"]["spliced_rows"]
    result = rollout(record, tracks, rows, planner, spec)
    metrics = judge(record, tracks, rows, int(attack["adversary_row"]), planner, spec, result=result)
    k0, ego = result.t0_step, result.ego
    path = result.states[ego, k0:][result.valid[ego, k0:], :2]
    out = {"spec": spec, "collision": bool(metrics["collision"]),
           "collision_time_s": metrics["collision_time_s"], "collision_any": bool(metrics["collision_any"]),
           "collision_before_t0": bool(metrics["collision_before_t0"]),
           "progress_m": float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()),
           "progress_to_collision_m": metrics["distance_m"], "min_gap_m": metrics["min_gap_m"],
           "rollout_s": result.wall_s}
    guard = traits_of(planner).guard
    if guard is not None:
        summary = guard.summary()
        out["guard"] = {k: summary[k] for k in GUARD_SUMMARY_KEYS}
        # when System 2 took over (s of the episode) and the TGAT's highest score then
        out["guard"]["interventions_s"] = [e["time_s"] for e in guard.log]
        out["guard"]["max_scores"] = [e["max_score"] for e in guard.log]
        out["guard"]["system1_ms_median"] = float(np.median(summary["system1_ms"])) if summary["system1_ms"] else None
        out["guard"]["system2_ms_median"] = float(np.median(summary["system2_ms"])) if summary["system2_ms"] else None
    return out
