"""Throughput of `riskmap collect`: windows per second with 1 and 2 worker processes.

Each configuration runs `--repeats` times into a fresh temporary directory (the whole command
path: env creation, simulation, window cutting, shard writes); the table reports medians and the
speed-up of 2 workers over 1 worker measured in the same process.

    .venv/bin/python experiments/bench_collect.py [--episodes 8] [--repeats 3] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from riskmap.data.collect import CollectConfig, collect


@dataclass(frozen=True)
class BenchArgs:
    envs: tuple[str, ...] = ("highway-v0", "intersection-v0")
    workers: tuple[int, ...] = (1, 2)
    episodes: int = 8
    repeats: int = 3
    seed: int = 100


def run_once(env_id: str, episodes: int, workers: int, seed: int) -> tuple[float, int]:
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        manifest = collect(CollectConfig(env_id, episodes, seed), Path(tmp) / "d", workers=workers,
                           progress=False)
        return time.perf_counter() - start, manifest["counts"]["windows"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=BenchArgs.episodes)
    parser.add_argument("--repeats", type=int, default=BenchArgs.repeats)
    parser.add_argument("--out", type=Path, default=Path("experiments/results/bench_collect.json"))
    cli = parser.parse_args()
    args = BenchArgs(episodes=cli.episodes, repeats=cli.repeats)
    rows = []
    for env_id in args.envs:
        per_workers = {}
        for workers in args.workers:
            runs = [run_once(env_id, args.episodes, workers, args.seed) for _ in range(args.repeats)]
            seconds = statistics.median(r[0] for r in runs)
            windows = runs[0][1]
            per_workers[workers] = windows / seconds
            rows.append({"env": env_id, "workers": workers, "episodes": args.episodes,
                         "windows": windows, "median_s": round(seconds, 3),
                         "windows_per_s": round(windows / seconds, 2),
                         "episodes_per_s": round(args.episodes / seconds, 3)})
        for row in rows:
            if row["env"] == env_id:
                row["speedup_vs_1_worker"] = round(row["windows_per_s"] / per_workers[1], 2)
    print(f"{'env':18s} {'workers':>7s} {'windows':>8s} {'median s':>9s} {'windows/s':>10s} "
          f"{'episodes/s':>11s} {'speed-up':>9s}")
    for r in rows:
        print(f"{r['env']:18s} {r['workers']:7d} {r['windows']:8d} {r['median_s']:9.2f} "
              f"{r['windows_per_s']:10.1f} {r['episodes_per_s']:11.2f} {r['speedup_vs_1_worker']:9.2f}")
    cli.out.parent.mkdir(parents=True, exist_ok=True)
    machine = {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
               "python": platform.python_version()}
    cli.out.write_text(json.dumps({"machine": machine, "args": vars(cli) | {"out": str(cli.out)},
                                   "rows": rows}, indent=2) + "\n")


if __name__ == "__main__":
    main()
