"""Open-loop plan quality of a checkpoint on held-out windows: ADE, FDE, goal error, SVF overlap.

For every window of a dataset collected with another seed than the training data:
    ADE / FDE      plan waypoints vs the recorded 6 s future (m)
    goal error     plan's last waypoint vs the centre of the goal cell the planner was given (m)
    overlap        Σ SVF ⊙ N / Σ SVF: share of the policy's expected visits on cells covered by
                   the ado agents' uncertainty map N (σ from the checkpoint's training)
Writes a JSON per checkpoint into --out and prints a table.

    .venv/bin/python experiments/eval_plans.py --data data/highway_heldout \
        --checkpoints checkpoints/highway.safetensors [more ...] --out experiments/results/plans
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from rasterize.frames import ego_from_grid, ego_from_world, ego_pose
from rasterize.maps import uncertainty_map
from riskmap.data.dataset import DemoDataset
from riskmap.planner.riskmap_planner import RiskMapPlanner


def window_errors(planner: RiskMapPlanner, dataset: DemoDataset, indices, sigma_x: float,
                  sigma_y: float) -> dict[str, list[float]]:
    """Per-window ADE, FDE, goal error, SVF overlap and planning time of `planner` on `indices`."""
    out = {"index": [], "ade_m": [], "fde_m": [], "goal_error_m": [], "overlap": [], "plan_ms": [],
           "plan_end_m": [], "demo_end_m": [], "end_short_m": [], "vi_ms": []}
    for i in indices:
        scene = dataset.scene(int(i))
        plan = planner.plan(scene)
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
             goal_variance: float | None = None) -> dict:
    planner = RiskMapPlanner.load(checkpoint, seed=seed, goal_variance=goal_variance)
    side = json.loads(Path(checkpoint).with_suffix(".json").read_text())
    sx, sy = side["maps"]["sigma_x"], side["maps"]["sigma_y"]
    dataset = DemoDataset(data, planner.grid.rows, raster=planner.raster)
    picks = range(len(dataset)) if limit is None else \
        np.unique(np.linspace(0, len(dataset) - 1, limit).astype(int))
    e = window_errors(planner, dataset, picks, sx, sy)

    def stats(x):
        return {"mean": float(np.mean(x)), "p90": float(np.percentile(x, 90))}

    return {"checkpoint": str(checkpoint), "data": str(data), "windows": len(e["ade_m"]),
            "ade_m": stats(e["ade_m"]), "fde_m": stats(e["fde_m"]),
            "goal_error_m": stats(e["goal_error_m"]), "svf_uncertainty_overlap": stats(e["overlap"]),
            "end_short_of_demo_m": stats(e["end_short_m"]), "goal_variance": planner.goal_variance,
            "plan_ms_median": float(np.median(e["plan_ms"])),
            "uncertainty_weight": side["irl"]["uncertainty_weight"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--checkpoints", type=Path, nargs="+", required=True)
    parser.add_argument("--limit", type=int, default=None, help="evaluate this many windows")
    parser.add_argument("--goal-variance", type=float, default=None,
                        help="cells²; override the checkpoint's goal variance at planning time")
    parser.add_argument("--out", type=Path, default=Path("experiments/results/plans"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{'checkpoint':40s} {'v':>5s} {'windows':>7s} {'ADE':>6s} {'FDE':>6s} {'goal':>6s} "
          f"{'overlap':>8s} {'short':>6s}")
    for ckpt in args.checkpoints:
        r = evaluate(ckpt, args.data, args.limit, goal_variance=args.goal_variance)
        suffix = "" if args.goal_variance is None else f"_gv{args.goal_variance:g}"
        name = f"{ckpt.parent.name}_{ckpt.stem}_{args.data.name}{suffix}.json"
        (args.out / name).write_text(json.dumps(r, indent=2) + "\n")
        print(f"{str(ckpt):40s} {r['uncertainty_weight']:5.1f} {r['windows']:7d} "
              f"{r['ade_m']['mean']:6.2f} {r['fde_m']['mean']:6.2f} {r['goal_error_m']['mean']:6.2f} "
              f"{r['svf_uncertainty_overlap']['mean']:8.4f} {r['end_short_of_demo_m']['mean']:6.1f}")


if __name__ == "__main__":
    main()
