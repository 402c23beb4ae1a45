"""Closed-loop driving speed: wall seconds per simulated second, highway-env's road plain and fast.

Every episode is driven twice in one process, once on an env made with `make_env(fast=False)`
(highway-env's own `Road`) and once with `fast=True` (`riskmap.sim.worlds.fast_road`), alternating
which goes first, so that a loaded machine slows both alike. The whole `drive_episode` is timed:
reset, every step, recording, measurements and, with a planner, planning. Medians over the
episodes of wall seconds (and process CPU seconds) per simulated second; the ratio is plain over
fast. Both runs of an episode must end alike (same simulated time, distance, collision and min
gap) or the script stops.

    .venv/bin/python experiments/bench_closed_loop.py [--episodes 3] [--checkpoint]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

from riskmap.planner.shipped import shipped_spec
from riskmap.registry import make_planner
from riskmap.sim.worlds.episode import make_env
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

ENVS = ("highway-v0", "intersection-v0")
SAME = ("simulated_s", "distance_m", "collided", "off_road", "min_gap_m", "mean_speed_mps")


def drive_timed(env, planner, config: DriveConfig, episode: int) -> tuple[float, float, dict]:
    """(wall s, CPU s, record) of one episode."""
    wall, cpu = time.perf_counter(), time.process_time()
    record = drive_episode(env, planner, config, episode)
    return time.perf_counter() - wall, time.process_time() - cpu, record


def bench(env_id: str, spec: str, episodes: int, seed: int, seconds: float | None) -> list[dict]:
    envs = {False: make_env(env_id, 10, fast=False), True: make_env(env_id, 10, fast=True)}
    planner = make_planner(spec, seed=seed)
    config = DriveConfig(env_id, episodes, seed, episode_s=seconds)
    drive_timed(envs[True], planner, DriveConfig(env_id, 1, seed, episode_s=2.0), 0)   # warm-up
    per = {False: [], True: []}
    for episode in range(episodes):
        order = (False, True) if episode % 2 == 0 else (True, False)
        records = {}
        for fast in order:
            wall, cpu, record = drive_timed(envs[fast], planner, config, episode)
            records[fast] = record
            per[fast].append((wall / record["simulated_s"], cpu / record["simulated_s"],
                              record["simulated_s"]))
        differ = [k for k in SAME if records[False][k] != records[True][k]]
        if differ:
            raise SystemExit(f"{env_id} {spec} episode {episode}: plain and fast roads differ in "
                             f"{differ}: {[records[False][k] for k in differ]} vs "
                             f"{[records[True][k] for k in differ]}")
    rows = []
    for fast in (False, True):
        rows.append({"env": env_id, "planner": spec, "fast": fast, "episodes": episodes,
                     "simulated_s": round(sum(r[2] for r in per[fast]), 1),
                     "wall_s_per_sim_s": round(statistics.median(r[0] for r in per[fast]), 4),
                     "cpu_s_per_sim_s": round(statistics.median(r[1] for r in per[fast]), 4)})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds per episode (default: the family's episode length)")
    parser.add_argument("--checkpoint", action="store_true",
                        help="also drive with the risk-map planners of checkpoints/")
    parser.add_argument("--out", type=Path, default=Path("experiments/results/bench_closed_loop.json"))
    cli = parser.parse_args()
    specs = ["idm"] + (["checkpoint"] if cli.checkpoint else [])
    rows = []
    for spec in specs:
        for env_id in ENVS:
            rows += bench(env_id, shipped_spec("riskmap", env_id) if spec == "checkpoint" else spec,
                          cli.episodes, cli.seed, cli.seconds)
    ratios = {}
    for plain, fast in zip(rows[0::2], rows[1::2]):
        ratios[f"{plain['env']} {plain['planner']}"] = {
            "wall": round(plain["wall_s_per_sim_s"] / fast["wall_s_per_sim_s"], 2),
            "cpu": round(plain["cpu_s_per_sim_s"] / fast["cpu_s_per_sim_s"], 2)}
    print(f"{'env':16s} {'planner':42s} {'fast':>5s} {'wall s/sim s':>13s} {'cpu s/sim s':>12s}")
    for r in rows:
        print(f"{r['env']:16s} {r['planner']:42s} {r['fast']!s:>5} {r['wall_s_per_sim_s']:13.4f} "
              f"{r['cpu_s_per_sim_s']:12.4f}")
    for key, ratio in ratios.items():
        print(f"ratio plain / fast, {key}: wall {ratio['wall']:.2f}x, cpu {ratio['cpu']:.2f}x")
    cli.out.parent.mkdir(parents=True, exist_ok=True)
    machine = {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
               "python": platform.python_version(),
               "loadavg_1min_at_end": round(os.getloadavg()[0], 2)}
    cli.out.write_text(json.dumps({"machine": machine, "args": vars(cli) | {"out": str(cli.out)},
                                   "rows": rows, "ratios": ratios}, indent=2) + "\n")


if __name__ == "__main__":
    main()
