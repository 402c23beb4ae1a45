"""Planner latency per call, by stage (raster, network, VI, SVF, sampler), at each resolution.

"total" is the time to the waypoints: raster, network, VI and sampler. The state visitation
(SVF) is computed only when a plan's `svf` is read (figures, open-loop metrics; never in closed
loop), so it is timed apart, here by reading it after each plan.

Scenes are highway-v0 moments with 2 s of recorded history. The risk-map generator carries the
shipped highway planner's weights (`--weights`) at every resolution: its layers do not depend on
the grid (the features are resized to G × G before the 1 × 1 head), and trained weights give the
policies a planner meets, whose paths end near the goal; a freshly initialised network
(`--weights random`) gives near-uniform risk, paths that wander to the horizon and a sampler
that costs more. Medians over `--calls` plans per resolution, after
`--warmup` calls; torch uses `--threads` threads. The value iteration is also timed against the
plain-Python loop reference of the tests on one small grid, in the same process, as a sanity
ratio of the vectorised implementation.

    .venv/bin/python experiments/bench_planner.py [--calls 30] [--threads 2]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from rasterize.config import raster_config_for_env
from riskmap.infra.checkpoint import load_weights
from riskmap.planner.model import ModelConfig, RiskMapGenerator
from riskmap.planner.riskmap_planner import RiskMapPlanner
from riskmap.planner.vi import soft_value_iteration
from riskmap.sim.worlds.episode import Episode, make_env

STAGES = ("raster", "network", "vi", "svf", "sampler", "total")


def highway_scenes(count: int) -> list:
    env = make_env("highway-v0")
    scenes = []
    for e in range(count):
        run = Episode(env, "highway-v0", seed=7, episode=e)
        for _ in range(30):
            run.step()
        scenes.append(run.recorder.scene(run.recorder.num_steps - 1, 2.0, 0.0))
    return scenes


def python_loop_vi(reward: np.ndarray, goal: np.ndarray, horizon: int) -> np.ndarray:
    h, w = reward.shape
    v = np.full((h, w), -np.inf)
    for _ in range(horizon):
        new = np.empty((h, w))
        for r in range(h):
            for c in range(w):
                qs = [reward[r, c] + goal[r, c]]
                for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                    if 0 <= r + dr < h and 0 <= c + dc < w:
                        qs.append(reward[r, c] + v[r + dr, c + dc])
                m = max(qs)
                new[r, c] = m + np.log(sum(np.exp(q - m) for q in qs))
        v = new
    return v


def vi_floor_ms(g: int, horizon: int, repeats: int = 5) -> dict:
    """What the CPU kernel of value iteration (riskmap.planner.vi) cannot go below at g×g: its
    per-cell work per backup — 5 exp, 1 log and 20 simple passes (4 copies, the max over 5
    options = 4 compares, 5 subtracts, the sum = 4 adds, 1 + 1 adds, the reward add) — at the
    throughput numpy reaches on 100 000-element float32 arrays (cache-resident, as the kernel's
    are, and long enough that call overhead vanishes); times cells × horizon. A floor for this
    formulation on one core, not for any algorithm."""
    x = np.linspace(-20.0, 0.0, 100_000, dtype=np.float32)
    out = np.empty_like(x)

    def per_element(fn) -> float:
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(20):
                fn()
            times.append((time.perf_counter() - t0) / 20)
        return min(times) / x.size

    exp = per_element(lambda: np.exp(x, out=out))
    log = per_element(lambda: np.log(np.abs(x, out=out) + 1.0, out=out)) / 3    # 3 passes
    simple = per_element(lambda: np.add(x, x, out=out))
    per_cell = 5 * exp + log + 20 * simple
    # A single fused pass (compiled code keeping a cell's options in registers) would still pay
    # the exponentials and the log: the floor of any kernel of this soft backup.
    fused = 5 * exp + log
    return {"resolution": g, "horizon": horizon, "ns_exp": round(1e9 * exp, 3),
            "ns_log": round(1e9 * log, 3), "ns_simple": round(1e9 * simple, 3),
            "floor_ms": round(1000 * per_cell * g * g * horizon, 2),
            "floor_fused_ms": round(1000 * fused * g * g * horizon, 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--resolutions", default="25,50,75,100")
    parser.add_argument("--weights", default="checkpoints/riskmap_highway",
                        help="a risk-map checkpoint whose weights every resolution uses, or random")
    parser.add_argument("--out", type=Path, default=Path("experiments/results/bench_planner.json"))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    scenes = highway_scenes(5)
    raster = raster_config_for_env("highway-v0")
    rows = []
    for g in (int(x) for x in args.resolutions.split(",")):
        model = RiskMapGenerator(ModelConfig(resolution=g)).eval()
        if args.weights != "random":
            model = load_weights(model, Path(args.weights), "pass --weights random")
        planner = RiskMapPlanner(model, raster, raster.grid(g), horizon=int(round(1.6 * g)),
                                 goal_variance=5.0)
        for i in range(args.warmup):
            planner.plan(scenes[i % len(scenes)])
        times = {s: [] for s in STAGES}
        for i in range(args.calls):
            plan = planner.plan(scenes[i % len(scenes)])
            _ = plan.svf            # computed on first read, timed apart from "total"
            for s in STAGES:
                times[s].append(plan.timings_s[s])
        row = {"resolution": g, "horizon": planner.horizon,
               **{f"{s}_ms": round(1000 * statistics.median(times[s]), 2) for s in STAGES}}
        rows.append(row)
        print(" ".join(f"{k}={v}" for k, v in row.items()), flush=True)

    # Same-process ratio against the plain reference on a 12x12 grid, horizon 20.
    rng = np.random.default_rng(0)
    reward, goal = -rng.random((12, 12)), rng.normal(size=(12, 12))
    t0 = time.perf_counter()
    ref = python_loop_vi(reward, goal, 20)
    t_ref = time.perf_counter() - t0
    t_ours = []
    for _ in range(20):
        t0 = time.perf_counter()
        ours = soft_value_iteration(torch.tensor(reward)[None], torch.tensor(goal)[None], 20)[0]
        t_ours.append(time.perf_counter() - t0)
    np.testing.assert_allclose(ours[0].numpy(), ref, atol=1e-9)
    ratio = t_ref / statistics.median(t_ours)
    print(f"value iteration 12x12 x 20: reference loop {1000 * t_ref:.1f} ms, ours "
          f"{1000 * statistics.median(t_ours):.2f} ms median (x{ratio:.0f} faster)")
    floor = vi_floor_ms(100, 160)
    vi_100 = next((row["vi_ms"] for row in rows if row["resolution"] == 100), None)
    print(f"value iteration floor at 100x100 x 160 on one core: {floor['floor_ms']} ms for this "
          f"formulation, {floor['floor_fused_ms']} ms for any fused kernel"
          + (f"; measured {vi_100} ms ({vi_100 / floor['floor_ms']:.1f}x the floor)" if vi_100 else ""))
    machine = {"cpus": os.cpu_count(), "machine": platform.machine(),
               "torch": torch.__version__, "threads": args.threads, "weights": args.weights}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"machine": machine, "rows": rows,
                                    "vi_reference_ratio": round(ratio, 1), "vi_floor": floor},
                                   indent=2) + "\n")


if __name__ == "__main__":
    main()
