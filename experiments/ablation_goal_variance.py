"""Goal variance 2 vs 5 on straight, slow-turn and large-turn scenes (planner paper Fig. 4 analogue).

The paper varies the goal map's variance and shows that a wide goal lets the plan settle short of
or beside the goal on turns, a narrow one pins it. Here the variance is varied at planning time
on the shipped checkpoints (trained with 5 cells²), on held-out windows sorted by how much the
human turned over the 6 s future:

    straight     |Δheading| < 10°
    slow turn    10° ≤ |Δheading| < 45°
    large turn   |Δheading| ≥ 45°

Per class and variance: mean ADE, FDE and goal error (plan end to goal cell centre); one PNG per
class with the same scene planned at both variances. Writes experiments/results/ablation_goal_variance/.

    .venv/bin/python experiments/ablation_goal_variance.py \
        --data data/highway_heldout data/intersection_heldout \
        --checkpoints checkpoints/riskmap_highway checkpoints/riskmap_intersection --limit 150
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from rasterize.frames import ego_from_grid, ego_from_world, ego_pose
from riskmap.data.dataset import DemoDataset
from riskmap.figures.ablation import pyplot, write_table
from riskmap.infra.atomic import write_json
from riskmap.planner.riskmap_planner import RiskMapPlanner

VARIANCES = (2.0, 5.0)               # cells²
CLASSES = (("straight", 0.0, 10.0), ("slow turn", 10.0, 45.0), ("large turn", 45.0, 360.0))


def heading_change_deg(scene) -> float:
    """|heading at the end of the recorded future − heading now|, degrees."""
    ego = scene.states[scene.ego_index]
    now, end = ego[scene.current_index], ego[-1]
    delta = np.arctan2(end[3], end[2]) - np.arctan2(now[3], now[2])
    return float(abs(np.degrees((delta + np.pi) % (2 * np.pi) - np.pi)))


def turn_class(degrees: float) -> str:
    return next(name for name, lo, hi in CLASSES if lo <= degrees < hi)


def plan_errors(planner: RiskMapPlanner, scene) -> tuple[dict, object]:
    plan = planner.plan(scene)
    origin, heading = ego_pose(scene)
    demo = ego_from_world(scene.ego_future_xy(), origin, heading)
    err = np.linalg.norm(plan.waypoints - demo, axis=1)
    goal = np.linalg.norm(plan.waypoints[-1] - ego_from_grid(plan.goal_cell, planner.grid))
    return {"ade_m": float(err.mean()), "fde_m": float(err[-1]), "goal_error_m": float(goal)}, plan


def example_png(scene, planner: RiskMapPlanner, plans: dict, path: Path, title: str) -> None:
    from rasterize.raster import rasterize_scene
    from riskmap.figures.panels import raster_to_rgb

    plt = pyplot()
    ext = planner.raster.extent
    origin, heading = ego_pose(scene)
    demo = np.concatenate([[[0.0, 0.0]], ego_from_world(scene.ego_future_xy(), origin, heading)])
    fig, ax = plt.subplots(figsize=(5.2, 5.6), dpi=110)
    ax.imshow(raster_to_rgb(rasterize_scene(scene, planner.raster)), interpolation="nearest",
              extent=(ext.left_m, -ext.right_m, -ext.back_m, ext.front_m), aspect="auto")
    ax.plot(demo[:, 1], demo[:, 0], "-o", color="#3ddc84", ms=3, lw=1.6, label="human (6 s)")
    colours = {2.0: "#ff66ff", 5.0: "#ffd43b"}
    for variance, (waypoints, goal_xy) in plans.items():
        xy = np.concatenate([[[0.0, 0.0]], waypoints])
        ax.plot(xy[:, 1], xy[:, 0], "-o", color=colours[variance], ms=3, lw=1.3,
                label=f"plan, goal variance {variance:g}")
        ax.plot(goal_xy[1], goal_xy[0], "*", color=colours[variance], ms=12, mec="black", mew=0.5)
    ax.set_xlim(ext.left_m, -ext.right_m)
    ax.set_ylim(-ext.back_m, ext.front_m)
    ax.set_xlabel("lateral y (m, + left of ego)")
    ax.set_ylabel("forward x (m)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, nargs="+", required=True)
    parser.add_argument("--checkpoints", type=Path, nargs="+", required=True,
                        help="one per --data, in the same order")
    parser.add_argument("--limit", type=int, default=150, help="windows per dataset, evenly spread")
    parser.add_argument("--out", type=Path, default=Path("experiments/results/ablation_goal_variance"))
    args = parser.parse_args()
    if len(args.data) != len(args.checkpoints):
        parser.error("pass one --checkpoints entry per --data entry")
    rows: dict = {}
    examples: dict = {}
    for data, checkpoint in zip(args.data, args.checkpoints, strict=True):
        planners = {v: RiskMapPlanner.load(checkpoint, goal_variance=v) for v in VARIANCES}
        dataset = DemoDataset(data, planners[2.0].grid.rows, raster=planners[2.0].raster)
        for i in np.unique(np.linspace(0, len(dataset) - 1, args.limit).astype(int)):
            scene = dataset.scene(int(i))
            cls = turn_class(heading_change_deg(scene))
            plans = {}
            for variance, planner in planners.items():
                errors, plan = plan_errors(planner, scene)
                rows.setdefault(cls, {}).setdefault(variance, []).append(errors)
                plans[variance] = plan.waypoints
            # Keep, per class, the window where the two variances differ most at the end.
            gap = float(np.linalg.norm(plans[2.0][-1] - plans[5.0][-1]))
            if cls not in examples or gap > examples[cls][0]:
                examples[cls] = (gap, data, int(i), checkpoint)
    table = {}
    for cls, _, _ in CLASSES:
        for variance in VARIANCES:
            entries = rows.get(cls, {}).get(variance, [])
            if entries:
                table.setdefault(cls, {})[f"{variance:g}"] = {
                    "windows": len(entries),
                    **{k: float(np.mean([e[k] for e in entries])) for k in entries[0]}}
    write_json(args.out / "results.json", {"data": [str(d) for d in args.data],
                                           "checkpoints": [str(c) for c in args.checkpoints],
                                           "table": table})
    lines = ["| scenes | windows | goal variance | ADE (m) | FDE (m) | goal error (m) |",
             "|---|---|---|---|---|---|"]
    for cls, by_variance in table.items():
        for variance, r in by_variance.items():
            lines.append(f"| {cls} | {r['windows']} | {variance} | {r['ade_m']:.2f} | {r['fde_m']:.2f} | "
                         f"{r['goal_error_m']:.2f} |")
    write_table(args.out, lines)
    for cls, (gap, data, index, checkpoint) in examples.items():
        planners = {v: RiskMapPlanner.load(checkpoint, goal_variance=v) for v in VARIANCES}
        scene = DemoDataset(data, planners[2.0].grid.rows, raster=planners[2.0].raster).scene(index)
        plans = {}
        for variance, planner in planners.items():
            plan = planner.plan(scene)
            plans[variance] = (plan.waypoints, ego_from_grid(plan.goal_cell, planner.grid))
        example_png(scene, planners[2.0], plans, args.out / f"{cls.replace(' ', '_')}.png",
                    f"{cls}: {Path(data).name} window {index} (|Δheading| "
                    f"{heading_change_deg(scene):.0f}°)")
    print(json.dumps({cls: e[2] for cls, e in examples.items()}))


if __name__ == "__main__":
    main()
