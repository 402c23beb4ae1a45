"""Open-loop plan quality of a risk-map checkpoint on held-out windows: ADE, FDE, goal error, SVF
overlap, and the choice of its planning-time goal variance.

For every window of a dataset collected with another seed than the training data:
    ADE / FDE      plan waypoints vs the recorded 6 s future (m)
    goal error     plan's last waypoint vs the centre of the goal cell the planner was given (m)
    overlap        Σ SVF ⊙ N / Σ SVF: share of the policy's expected visits on cells covered by
                   the ado agents' uncertainty map N (σ from the checkpoint's training)

`tune_goal_variance` (`riskmap tune-goal-variance`): the goal enters value iteration as
−d²/(2σ²) (cells) against per-cell rewards of about −1 to −2, so the trained σ² = 5 lets plans stop
~8 cells short of the goal (`RiskMapPlanner.load`). It plans every candidate σ² on the same
held-out windows and writes the one with the lowest mean ADE against the recorded future into
the sidecar's `planning` section, with the evidence, so that `riskmap:PATH` plans with it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from rasterize.frames import ego_from_grid, ego_from_world, ego_pose
from rasterize.maps import uncertainty_map
from riskmap.data.dataset import DemoDataset, with_human_goal
from riskmap.data.groups import windows_of_groups
from riskmap.infra.atomic import write_json
from riskmap.infra.checkpoint import read_sidecar
from riskmap.planner.riskmap_planner import RiskMapPlanner, load_planner


def window_errors(planner: RiskMapPlanner, dataset: DemoDataset, indices, sigma_x: float,
                  sigma_y: float, goal: str = "route") -> dict[str, list[float]]:
    """Per-window ADE, FDE, goal error, SVF overlap and planning time of `planner` on `indices`,
    towards the route rule's goal or (`goal="human"`) the human's own end."""
    out = {"index": [], "ade_m": [], "fde_m": [], "goal_error_m": [], "overlap": [], "plan_ms": [],
           "plan_end_m": [], "demo_end_m": [], "end_short_m": [], "vi_ms": []}
    for i in indices:
        scene = dataset.scene(int(i))
        plan = planner.plan(with_human_goal(scene) if goal == "human" else scene)
        origin, heading = ego_pose(scene)
        demo = ego_from_world(scene.ego_future_xy(), origin, heading)
        err = np.linalg.norm(plan.waypoints - demo, axis=1)
        unc = uncertainty_map(scene, planner.grid, sigma_x, sigma_y)
        out["index"].append(int(i))
        out["ade_m"].append(float(err.mean()))
        out["fde_m"].append(float(err[-1]))
        out["goal_error_m"].append(float(np.linalg.norm(
            plan.waypoints[-1] - ego_from_grid(plan.goal_cell, planner.grid))))
        out["overlap"].append(float((plan.svf * unc).sum() / max(plan.svf.sum(), 1e-9)))
        out["plan_ms"].append(1000 * plan.timings_s["total"])
        out["vi_ms"].append(1000 * plan.timings_s["vi"])
        out["plan_end_m"].append(float(np.linalg.norm(plan.waypoints[-1])))   # how far it goes
        out["demo_end_m"].append(float(np.linalg.norm(demo[-1])))
        # How far the plan's end lies behind (+) or beyond (−) the demonstration's, along x.
        out["end_short_m"].append(float(demo[-1, 0] - plan.waypoints[-1, 0]))
    return out


def evaluate(checkpoint: Path, data: Path, limit: int | None = None, seed: int = 0,
             goal_variance: float | None = None, goal: str = "route", timing: str | None = None,
             indices=None, keep_gap: bool | None = None) -> dict:
    """Plan quality of `checkpoint` on `limit` windows of `data` spread evenly (all if None; or
    exactly `indices`), towards `goal` (route or human), waypoints timed by `timing` (default:
    the checkpoint's)."""
    import dataclasses

    planner = load_planner(checkpoint, seed=seed, goal_variance=goal_variance)
    changes = {k: v for k, v in (("timing", timing), ("keep_gap", keep_gap)) if v is not None}
    if changes and not isinstance(planner, RiskMapPlanner):
        raise InputError(f"checkpoint {checkpoint} is a space-time planner, which times its plan "
                         "itself; drop --timing and --keep-gap")
    planner.sampler = dataclasses.replace(planner.sampler, **changes)
    side = read_sidecar(checkpoint)
    sx, sy = side["maps"]["sigma_x"], side["maps"]["sigma_y"]
    dataset = DemoDataset(data, planner.grid.rows, raster=planner.raster)
    picks = range(len(dataset)) if limit is None else \
        np.unique(np.linspace(0, len(dataset) - 1, limit).astype(int))
    e = window_errors(planner, dataset, picks if indices is None else indices, sx, sy, goal)

    def stats(x):
        return {"mean": float(np.mean(x)), "p90": float(np.percentile(x, 90))}

    return {"checkpoint": str(checkpoint), "data": str(data), "windows": len(e["ade_m"]),
            "ade_m": stats(e["ade_m"]), "fde_m": stats(e["fde_m"]),
            "goal_error_m": stats(e["goal_error_m"]), "svf_uncertainty_overlap": stats(e["overlap"]),
            "end_short_of_demo_m": stats(e["end_short_m"]), "goal_variance": planner.goal_variance,
            "plan_ms_median": float(np.median(e["plan_ms"])),
            "uncertainty_weight": side["irl"]["uncertainty_weight"]}


def group_windows(data: Path, groups: tuple[str, ...], limit: int | None) -> list[int]:
    """Indices of the windows of recorded `groups` (names or configuration numbers), at most
    `limit` spread evenly."""
    chosen = windows_of_groups(DemoDataset(data), groups)
    if limit is not None and len(chosen) > limit:
        chosen = [chosen[i] for i in np.unique(np.linspace(0, len(chosen) - 1, limit).astype(int))]
    return chosen


def tune_goal_variance(checkpoint: Path, data: Path, candidates: tuple[float, ...], limit: int = 60,
                       write: bool = True, report=print, goal: str = "route",
                       groups: tuple[str, ...] | None = None, timing: str | None = None,
                       keep_gap: bool | None = None) -> dict:
    """Evaluate each candidate goal variance (cells²) towards `goal`; record the lowest-ADE one
    in the sidecar's `planning` section (`goal_variance` for the route rule's goal, which
    `riskmap:PATH` plans with; `human_goal_variance` for the human's end) unless `write` is
    False. `groups`: only windows of these recorded configurations. `timing` (uniform or
    kinematic: `riskmap.planner.sampler.SamplerConfig`) plans with that waypoint timing and
    records it as `planning.timing`; `keep_gap` likewise (`riskmap.planner.gap_keeping`).
    Returns that section."""
    checkpoint = Path(checkpoint)
    weights = checkpoint.with_suffix(".safetensors")
    indices = group_windows(data, groups, limit) if groups else None
    rows = []
    for variance in candidates:
        r = evaluate(weights, data, limit, goal_variance=float(variance), goal=goal, indices=indices,
                     timing=timing, keep_gap=keep_gap)
        rows.append({"goal_variance": float(variance), "windows": r["windows"],
                     "ade_m": r["ade_m"]["mean"], "fde_m": r["fde_m"]["mean"],
                     "goal_error_m": r["goal_error_m"]["mean"],
                     "end_short_of_demo_m": r["end_short_of_demo_m"]["mean"]})
        report(" ".join(f"{k}={v:.2f}" if isinstance(v, float) else f"{k}={v}" for k, v in rows[-1].items()))
    best = min(rows, key=lambda row: row["ade_m"])
    sidecar = checkpoint.with_suffix(".json")
    planning = json.loads(sidecar.read_text()).get("planning", {})
    if goal == "route":
        planning |= {"goal_variance": best["goal_variance"], "chosen_by": "lowest mean ADE",
                     "held_out_data": str(data), "groups": list(groups or []), "candidates": rows}
    else:
        planning |= {"human_goal_variance": best["goal_variance"], "human_chosen_by": "lowest mean ADE",
                     "human_data": str(data), "human_groups": list(groups or []),
                     "human_candidates": rows}
    if timing is not None:
        planning["timing"] = timing
    if keep_gap is not None:
        planning["keep_gap"] = keep_gap
    if write:
        write_json(sidecar, {**json.loads(sidecar.read_text()), "planning": planning})
    return planning
