"""Choose the gap-keeping headway in closed loop on training configurations of recorded traffic.

Drives every recorded demonstrator of the given CommonRoad files (log replay, the human's goal)
with a risk-map checkpoint whose gap keeping (`riskmap.planner.gap_keeping`) uses each candidate
headway, and prints collisions (at fault), ADE and goal error per headway. Use files of the
configurations the checkpoint trained on, so that the evaluation configurations stay unseen.

    .venv/bin/python experiments/gap_keeping_headway.py --checkpoint checkpoints/riskmap_us101 \
        --goal-variance 0.25 --headways 0,0.5,1.0 --workers 2 --out experiments/results/us101/gap_headway.json \
        DIR/USA_US101-{9,10,12,13}_1_T-1.xml
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def _episode(task: tuple) -> dict:
    import torch

    import riskmap.planner.riskmap_planner as riskmap_planner
    from riskmap.evaluation.sources import recorded_traffic
    from riskmap.planner import gap_keeping
    from riskmap.planner.riskmap_planner import RiskMapPlanner
    from riskmap.sim.worlds.commonroad_replay import ReplayConfig, replay_commonroad_episode

    torch.set_num_threads(1)
    checkpoint, goal_variance, headway, path, vehicle = task
    config = gap_keeping.GapKeepingConfig(headway_s=headway)
    riskmap_planner.keep_gap = lambda w, s, dt, **kw: gap_keeping.keep_gap(w, s, dt, config, **kw)
    planner = RiskMapPlanner.load(checkpoint, goal_variance=goal_variance)
    record = replay_commonroad_episode(recorded_traffic(Path(path)), vehicle, planner,
                                       config=ReplayConfig(goal="human"))
    return {"headway_s": headway, "vehicle": vehicle, "file": Path(path).name,
            "collided": bool(record["collided"]),
            "at_fault": bool(record["collision"]) and record["collision"]["other_ahead"],
            "ade_m": record["ade_m"], "goal_error_m": record["goal_error_m"]}


def main() -> None:
    from riskmap.data.collect_commonroad import CommonRoadCollectConfig, unique_demonstrators
    from riskmap.infra.atomic import write_json
    from riskmap.infra.parallel import run_parallel

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recordings", nargs="+")
    parser.add_argument("--checkpoint", required=True)
    parser.add_argument("--goal-variance", type=float, default=None)
    parser.add_argument("--headways", default="0,0.5,1.0")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    demos, traffics, _ = unique_demonstrators([Path(p).resolve() for p in args.recordings],
                                              CommonRoadCollectConfig(files=(), smoothing_s=0.0))
    headways = [float(h) for h in args.headways.split(",")]
    tasks = [(args.checkpoint, args.goal_variance, h, str(d.path), int(traffics[d.path].ids[d.agent]))
             for h in headways for d in demos]
    rows = [result for _, result in run_parallel(_episode, tasks, args.workers)]
    summary = {}
    for h in headways:
        mine = [r for r in rows if r["headway_s"] == h]
        summary[str(h)] = {"episodes": len(mine), "collisions": sum(r["collided"] for r in mine),
                           "at_fault": sum(r["at_fault"] for r in mine),
                           "ade_m": float(np.mean([r["ade_m"] for r in mine])),
                           "goal_error_m": float(np.mean([r["goal_error_m"] for r in mine]))}
        print(h, summary[str(h)], flush=True)
    write_json(Path(args.out), {"recordings": args.recordings, "checkpoint": args.checkpoint,
                                "goal_variance": args.goal_variance, "summary": summary, "episodes": rows})


if __name__ == "__main__":
    main()
