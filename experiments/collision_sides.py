"""Where the other vehicle was when a planner's ego collided in log mode: ahead of, beside or behind it.

In log mode the other vehicles replay the human's record and do not react, so a slow ego is run
into from behind; this tells such collisions apart from the ego driving into someone.

    python experiments/collision_sides.py --out out/table1/intersection --planner riskmap:checkpoints/riskmap_intersection --episodes 0 3 5
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from rasterize.frames import ego_from_world, heading_angle
from riskmap.evaluation.sources import EnvSource
from riskmap.registry import cached_planner
from riskmap.sim.worlds.episode import cached_env
from riskmap.sim.worlds.log_replay import HumanLog, LogReplayEpisode


def collision_side(out: Path, spec: str, episode: int) -> dict:
    from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

    meta = json.loads((out / "run.json").read_text())["config"]
    config = EnvSource(meta["env_id"], meta["episodes"], meta["seed"], meta["mode"], episode_s=meta["episode_s"])
    log = HumanLog.load(out / "logs" / f"episode_{episode:06d}.npz")
    env = cached_env(config.env_id, config.control_hz)
    run = LogReplayEpisode(env, config.env_id, config.seed, episode, log, config.control_hz)
    drive_episode(env, cached_planner(spec, config.seed), DriveConfig(config.env_id, 1, config.seed,
                  episode_s=config.episode_s), episode, run=run)
    if not run.crashed:
        return {"episode": episode, "collided": False}
    tracks = run.recorder.tracks()
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    ego_id, k = run.recorder.ego_id, run.steps
    ego = states[ego_id, k]
    others = [a for a in range(len(sizes)) if a != ego_id and valid[a, k]]
    nearest = min(others, key=lambda a: np.linalg.norm(states[a, k, :2] - ego[:2]))
    rel = ego_from_world(states[nearest, k, :2], ego[:2], float(heading_angle(ego[2:4])))
    side = "behind" if rel[0] < -2.0 else "ahead" if rel[0] > 2.0 else "beside"
    return {"episode": episode, "collided": True, "time_s": k * run.dt, "other_in_ego_frame_m":
            rel.round(2).tolist(), "side": side, "ego_speed_mps": float(ego[4]),
            "other_speed_mps": float(states[nearest, k, 4])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", required=True, help="a `riskmap evaluate --mode log` directory")
    parser.add_argument("--planner", required=True)
    parser.add_argument("--episodes", type=int, nargs="+", required=True)
    args = parser.parse_args()
    for e in args.episodes:
        print(json.dumps(collision_side(Path(args.out), args.planner, e)), flush=True)


if __name__ == "__main__":
    main()
