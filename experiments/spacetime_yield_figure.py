"""The space-time planner at a yield: r_t and D_t on held-out windows where the human waits.

A window counts as a yield when the human is moving now (> 1 m/s), covers less than half of what
its present speed would cover over the next 3 s, and another agent is predicted (from the
present) within 10 m of the human's recorded path in that time. For the first `--count` such
windows (in dataset order) it writes the plan panels and the per-step strip, and prints how far
the plan and the human go in 3 s.

    .venv/bin/python experiments/spacetime_yield_figure.py --checkpoint checkpoints/riskmap_st_intersection \
        --data data/intersection_heldout --out experiments/results/spacetime --count 2
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rasterize.frames import ego_from_world, ego_pose
from rasterize.predict import predict_along_lanes
from riskmap.data.dataset import DemoDataset
from riskmap.figures.panels import save_plan_panels, save_spacetime_strip
from riskmap.planner.riskmap_planner import load_planner

HORIZON_S = 3.0


def is_yield(scene) -> bool:
    speed = float(scene.ego_state()[4])
    if speed < 1.0:
        return False
    steps = round(HORIZON_S / scene.dt)
    future = scene.ego_future_xy()[:steps]
    travelled = float(np.linalg.norm(future[-1] - scene.ego_state()[:2]))
    if travelled > 0.5 * speed * HORIZON_S:
        return False
    xy, _ = predict_along_lanes(scene.past(), HORIZON_S, 0.5)
    others = scene.valid[:, scene.current_index].copy()
    others[scene.ego_index] = False
    if not others.any():
        return False
    gaps = np.linalg.norm(xy[others][:, :, None] - future[None, None], axis=-1)
    return bool(np.nanmin(gaps) < 10.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", required=True)
    parser.add_argument("--data", required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--count", type=int, default=2)
    args = parser.parse_args()
    planner = load_planner(args.checkpoint)
    dataset = DemoDataset(args.data, planner.grid.rows, raster=planner.raster)
    found = 0
    for i in range(len(dataset)):
        scene = dataset.scene(i)
        if not is_yield(scene):
            continue
        plan = planner.plan(scene)
        origin, heading = ego_pose(scene)
        demo = ego_from_world(scene.ego_future_xy(), origin, heading)
        k = round(HORIZON_S / 0.5) - 1
        title = (f"window {i}: ego {scene.ego_state()[4]:.1f} m/s; in {HORIZON_S:g} s the human goes "
                 f"{np.linalg.norm(demo[k]):.1f} m, the plan {np.linalg.norm(plan.waypoints[k]):.1f} m")
        print(title)
        save_plan_panels(scene, plan, planner.raster, planner.grid, args.out / f"yield_{i:05d}.png", title)
        save_spacetime_strip(plan, planner.grid, args.out / f"yield_{i:05d}_steps.png", title, demo_xy=demo)
        found += 1
        if found >= args.count:
            break
    print(f"{found} yield windows drawn into {args.out}")


if __name__ == "__main__":
    main()
