"""Time per decision step of the guard: System 1 (neighbour choice, features, TGAT) and System 2
(AgentSpeak reasoning cycle), on scenes from closed-loop IDM episodes.

    .venv/bin/python experiments/bench_guard.py --episodes 2 --out experiments/results/guard/bench_guard.json

Scenes are cut at every decision step (2 Hz) of natural highway and intersection episodes; each
scene is then timed `--repeats` times. Medians and 90th percentiles in milliseconds.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np
import torch

from rasterize.tracks import Tracks
from riskmap.guard.events import nearest_neighbours
from riskmap.guard.guarded import GUARD_CHECKPOINT, GuardConfig, obstacle_ahead, system2_config
from riskmap.guard.predictor import AccidentPredictor
from riskmap.guard.system2 import DecelerationAgent
from riskmap.infra.atomic import write_json
from riskmap.sim.loop.plan import HumanDriver
from riskmap.sim.worlds.episode import make_env
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode


class _SceneTap(HumanDriver):
    """The IDM ego, with a hook that cuts a 6-segment scene at every decision step."""

    def __init__(self):
        self.scenes = []

    def attach(self, run) -> None:
        step = run.step

        def step_and_cut() -> None:    # wraps this episode's step only
            step()
            rec = run.recorder
            if (rec.num_steps - 1) % 5 == 0:
                self.scenes.append(rec.scene(rec.num_steps - 1, history_s=2.5, future_s=0.0, dt_s=0.5,
                                             radius_m=80.0, lanes=False))

        run.step = step_and_cut


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--checkpoint", default=GUARD_CHECKPOINT)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    predictor = AccidentPredictor.load(args.checkpoint)
    config = GuardConfig()
    results = {"machine": platform.machine(), "python": platform.python_version(), "torch": torch.__version__,
               "threads": 1, "repeats": args.repeats, "envs": {}}
    for env_id in ("highway-v0", "intersection-v0"):
        tap = _SceneTap()
        env = make_env(env_id, 10)
        for episode in range(args.episodes):
            drive_episode(env, tap, DriveConfig(env_id, args.episodes, seed=200), episode)
        agent = DecelerationAgent(system2_config(config))
        s1, s2 = [], []
        for _ in range(args.repeats):
            for scene in tap.scenes:
                t0 = time.perf_counter()
                neighbours = nearest_neighbours(scene, config.neighbours)
                scores, ttcs = predictor.score(Tracks.of_scene(scene), scene.ego_index, neighbours, scene.current_index, 1)
                alert = bool(len(scores) and scores.max() >= predictor.alert_threshold)
                ttc = float(ttcs[scores.argmax()]) if alert else None
                ahead = obstacle_ahead(scene, config.obstacle_ahead_m, config.obstacle_lateral_m)
                t1 = time.perf_counter()
                agent.decide(alert, float(scene.ego_state()[4]), ahead, ttc)
                t2 = time.perf_counter()
                s1.append(1000 * (t1 - t0))
                s2.append(1000 * (t2 - t1))
        s1, s2 = np.array(s1), np.array(s2)
        results["envs"][env_id] = {
            "steps": len(s1), "scenes": len(tap.scenes),
            "system1_ms_median": float(np.median(s1)), "system1_ms_p90": float(np.percentile(s1, 90)),
            "system2_ms_median": float(np.median(s2)), "system2_ms_p90": float(np.percentile(s2, 90)),
            "total_ms_median": float(np.median(s1 + s2)), "total_ms_p90": float(np.percentile(s1 + s2, 90))}
        print(env_id, results["envs"][env_id], flush=True)
    write_json(args.out, results)


if __name__ == "__main__":
    main()
