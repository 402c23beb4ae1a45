"""Log-replay closed loop on CommonRoad recordings: planners drive the recorded demonstrators.

Every vehicle that `riskmap collect --from-commonroad` makes a demonstrator is handed over to
each planner 2 s into its record and driven to the end of its record among the replayed traffic
(`riskmap.sim.worlds.commonroad_replay`). Planners: `replay` (the log itself, tracked by the controller:
the harness's own error floor), `cv`, `riskmap:PATH`, and `finetuned:RUNS` (for each vehicle
the fold checkpoint of experiments/commonroad_finetune.py that held that vehicle out).

    .venv/bin/python experiments/commonroad_replay.py --recordings tests/fixtures/commonroad \
        --planners replay cv riskmap:checkpoints/riskmap_highway finetuned:runs/commonroad_finetune
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from rasterize.commonroad.reader import load_scenario
from rasterize.commonroad.tracks import RecordedTraffic
from riskmap.data.collect_commonroad import CommonRoadCollectConfig, demonstrators, scenario_files
from riskmap.infra.atomic import write_json
from riskmap.registry import make_planner
from riskmap.sim.worlds.commonroad_replay import RecordedFuturePlanner, replay_commonroad_episode


def _planner(spec: str, traffic: RecordedTraffic, vehicle_id: int, episode: int, folds: int):
    if spec == "replay":
        return RecordedFuturePlanner(traffic, vehicle_id)
    if spec.startswith("finetuned:"):
        return make_planner(f"riskmap:{Path(spec.split(':', 1)[1]) / f'fold_{episode % folds}'}")
    return make_planner(spec)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recordings", nargs="+", required=True, help="CommonRoad files or dirs")
    parser.add_argument("--planners", nargs="+", default=["replay", "cv"])
    parser.add_argument("--folds", type=int, default=4, help="folds of the fine-tuning run")
    parser.add_argument("--out", type=Path, default=Path("experiments/results/commonroad"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = CommonRoadCollectConfig(files=())
    records = {spec: [] for spec in args.planners}
    episode = 0
    for path in scenario_files(args.recordings):
        traffic = RecordedTraffic(load_scenario(path), path.stem)
        for agent, _ in demonstrators(traffic, config):
            vehicle = int(traffic.ids[agent])
            for spec in args.planners:
                planner = _planner(spec, traffic, vehicle, episode, args.folds)
                result = replay_commonroad_episode(traffic, vehicle, planner)
                records[spec].append(result)
                print(f"{spec:45s} {traffic.name} {vehicle}: collided {result['collided']}, "
                      f"{result['collision']}, off-road {result['off_road']}, ADE {result['ade_m']:.2f} m, "
                      f"goal error {result['goal_error_m']:.2f} m", flush=True)
            episode += 1

    def summary(rs):
        safe = [not (r["collided"] or r["off_road"]) for r in rs]
        return {"episodes": len(rs), "safety_pct": 100.0 * float(np.mean(safe)),
                "collisions": int(sum(r["collided"] for r in rs)),
                "collisions_from_behind": int(sum(bool(r["collision"]) and not r["collision"]["other_ahead"]
                                                  for r in rs)),
                "off_road": int(sum(r["off_road"] for r in rs)),
                "ade_m": float(np.mean([r["ade_m"] for r in rs])),
                "goal_error_m": float(np.mean([r["goal_error_m"] for r in rs])),
                "distance_m": float(np.mean([r["distance_m"] for r in rs])),
                "human_distance_m": float(np.mean([r["human_distance_m"] for r in rs])),
                "simulated_s": float(np.mean([r["simulated_s"] for r in rs]))}

    result = {spec: {"summary": summary(rs), "episodes": rs} for spec, rs in records.items()}
    write_json(args.out / "replay.json", result)
    table = [("| planner | episodes | Safety % | collisions (struck from behind) | off-road | ADE (m) | "
              "goal error (m) | driven (m) | human (m) | mean length (s) |"),
             "|---|---|---|---|---|---|---|---|---|---|"]
    for spec, r in result.items():
        s = r["summary"]
        table.append(f"| {spec} | {s['episodes']} | {s['safety_pct']:.0f} | {s['collisions']} "
                     f"({s['collisions_from_behind']}) | "
                     f"{s['off_road']} | {s['ade_m']:.2f} | {s['goal_error_m']:.2f} | "
                     f"{s['distance_m']:.1f} | {s['human_distance_m']:.1f} | {s['simulated_s']:.1f} |")
    (args.out / "replay.md").write_text("\n".join(table) + "\n")
    print("\n".join(table))


if __name__ == "__main__":
    main()
