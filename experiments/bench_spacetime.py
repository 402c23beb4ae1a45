"""Plan latency of the space-time planner beside the spatial one, by stage, in one process.

The two planners plan the same highway-v0 moments (2 s of history, the scenes of
`bench_planner.py`), interleaved call by call, so that both see the same machine state; medians
over `--calls` plans after `--warmup`. "total" is the time to the waypoints (raster, network,
value iteration, sampler); the spatial planner's raster stage holds the raster, the space-time
planner's also its per-step evidence (predicted footprints and red stop lines for each step).
Visitation is read only by figures and open-loop metrics (`svf`), so it is timed apart.

    .venv/bin/python experiments/bench_spacetime.py --spatial checkpoints/riskmap_highway \
        --spacetime checkpoints/riskmap_st_highway [--also NAME=CHECKPOINT ...] [--calls 40] \
        [--threads 2] [--out FILE.json]

`--also` adds further planners to the same interleaved rounds (for instance a space-time
checkpoint trained on a coarser raster, `riskmap train --raster-px 100`); every row's total is
also given as a ratio to the spatial planner's.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import torch

from riskmap.planner.riskmap_planner import load_planner

STAGES = ("raster", "network", "vi", "sampler", "total", "svf")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spatial", default="checkpoints/riskmap_highway")
    parser.add_argument("--spacetime", default="checkpoints/riskmap_st_highway")
    parser.add_argument("--also", action="append", default=[], metavar="NAME=CHECKPOINT",
                        help="another planner to time in the same rounds")
    parser.add_argument("--calls", type=int, default=40)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    from bench_planner import highway_scenes

    scenes = highway_scenes(8)
    planners = {"spatial": load_planner(args.spatial), "spacetime": load_planner(args.spacetime)}
    for entry in args.also:
        name, sep, path = entry.partition("=")
        if not sep or not name or not path or name in planners:
            parser.error(f"--also {entry!r}: give NAME=CHECKPOINT with a new NAME")
        planners[name] = load_planner(path)
    times = {name: {stage: [] for stage in STAGES} for name in planners}
    for call in range(args.warmup + args.calls):
        scene = scenes[call % len(scenes)]
        for name, planner in planners.items():
            plan = planner.plan(scene)
            started = time.perf_counter()
            _ = plan.svf
            svf_s = time.perf_counter() - started
            if call >= args.warmup:
                for stage in STAGES[:-1]:
                    times[name][stage].append(plan.timings_s[stage])
                times[name]["svf"].append(svf_s)
    medians = {name: {stage: 1000 * statistics.median(v) for stage, v in stages.items()}
               for name, stages in times.items()}
    width = max(10, *map(len, planners))
    print(f"{'planner':<{width}} " + " ".join(f"{s + ' ms':>11}" for s in STAGES) + "  raster px")
    for name, row in medians.items():
        print(f"{name:<{width}} " + " ".join(f"{row[s]:11.1f}" for s in STAGES)
              + f"  {planners[name].raster.rows:9d}")
    ratios = {name: row["total"] / medians["spatial"]["total"] for name, row in medians.items()}
    ratio = ratios["spacetime"]
    print(f"space-time / spatial total: {ratio:.2f}x; value iteration "
          f"{medians['spacetime']['vi']:.1f} vs {medians['spatial']['vi']:.1f} ms")
    if args.out:
        args.out.write_text(json.dumps({
            "medians_ms": medians, "ratio_total": ratio, "ratios_to_spatial": ratios,
            "raster_px": {name: planner.raster.rows for name, planner in planners.items()},
            "calls": args.calls,
            "threads": args.threads, "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count(), "torch": torch.__version__}, indent=2) + "\n")


if __name__ == "__main__":
    main()
