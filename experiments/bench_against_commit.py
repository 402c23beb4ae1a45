"""Value iteration, state visitation and sampler of this tree against an earlier commit's, in one process.

Loads `riskmap/planner/vi.py` and `riskmap/planner/sampler.py` as they were at `--commit` (git show) next to the
current ones, checks that both give bitwise-equal results on the same inputs, and times them
interleaved, so that the ratio holds on a busy machine where absolute times do not.
Medians over `--repeats`; policies come from the shipped highway checkpoint on held-out windows.

    .venv/bin/python experiments/bench_against_commit.py --commit 189959f \
        --data data/highway_heldout [--repeats 15] [--threads 1]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

import riskmap.planner.sampler as sampler_now
import riskmap.planner.vi as vi_now
from rasterize.maps import start_cell
from riskmap.data.dataset import DemoDataset
from riskmap.planner.riskmap_planner import RiskMapPlanner

ROOT = Path(__file__).resolve().parents[1]


def module_at(commit: str, relpath: str, name: str, workdir: Path):
    source = subprocess.run(["git", "show", f"{commit}:{relpath}"], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout
    path = workdir / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def timed(fn, *args, **kwargs) -> float:
    t0 = time.perf_counter()
    fn(*args, **kwargs)
    return time.perf_counter() - t0


def compare(then_fn, now_fn, args: tuple, repeats: int) -> tuple[dict, tuple]:
    """Bitwise equality of the two functions' tensor outputs on `args`, and their median times
    over `repeats` interleaved calls; also returns the current function's output."""
    then, now = then_fn(*args), now_fn(*args)
    equal = all(torch.equal(a, b) for a, b in zip(then, now, strict=True))
    t_then, t_now = [], []
    for _ in range(repeats):
        t_then.append(timed(then_fn, *args))
        t_now.append(timed(now_fn, *args))
    return {"bitwise_equal": equal, "then_ms": 1000 * statistics.median(t_then),
            "now_ms": 1000 * statistics.median(t_now)}, now


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commit", required=True)
    parser.add_argument("--data", type=Path, default=Path("data/highway_heldout"))
    parser.add_argument("--checkpoint", default="checkpoints/riskmap_highway")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("experiments/results/bench_against_commit.json"))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        vi_then = module_at(args.commit, "riskmap/planner/vi.py", "vi_then", Path(tmp))
        sampler_then = module_at(args.commit, "riskmap/planner/sampler.py", "sampler_then", Path(tmp))
    rows = []
    for g in (50, 100):
        horizon = round(1.6 * g)
        rng = torch.Generator().manual_seed(g)
        reward = -3.0 * torch.rand((1, g, g), generator=rng)
        goal = -10.0 * torch.rand((1, g, g), generator=rng)
        row, (_, policy) = compare(vi_then.soft_value_iteration, vi_now.soft_value_iteration,
                                   (reward, goal, horizon), args.repeats)
        rows.append({"stage": "vi", "resolution": g, **row})
        start = torch.tensor([[g - 5, g // 2]])
        row, _ = compare(vi_then.state_visitation, vi_now.state_visitation, (policy, start, horizon),
                         args.repeats)
        rows.append({"stage": "svf", "resolution": g, **row})
    planner = RiskMapPlanner.load(args.checkpoint)
    dataset = DemoDataset(args.data, planner.grid.rows, raster=planner.raster)
    policies = [torch.from_numpy(planner.plan(dataset.scene(i)).policy)
                for i in np.linspace(0, len(dataset) - 1, 5).astype(int)]
    start = start_cell(planner.grid)
    equal, t_then, t_now = True, [], []
    for k in range(args.repeats):
        policy = policies[k % len(policies)]
        a = sampler_then.sample_trajectory(policy, start, planner.horizon, planner.grid, seed=k)
        b = sampler_now.sample_trajectory(policy, start, planner.horizon, planner.grid, seed=k)
        equal &= bool(np.array_equal(a, b))
        t_then.append(timed(sampler_then.sample_trajectory, policy, start, planner.horizon,
                            planner.grid, seed=k))
        t_now.append(timed(sampler_now.sample_trajectory, policy, start, planner.horizon,
                           planner.grid, seed=k))
    rows.append({"stage": "sampler", "resolution": planner.grid.rows, "bitwise_equal": equal,
                 "then_ms": 1000 * statistics.median(t_then), "now_ms": 1000 * statistics.median(t_now)})
    for row in rows:
        row["speedup"] = round(row["then_ms"] / row["now_ms"], 2)
        row["then_ms"], row["now_ms"] = round(row["then_ms"], 2), round(row["now_ms"], 2)
        print(" ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"commit": args.commit, "threads": args.threads, "rows": rows},
                                   indent=2) + "\n")


if __name__ == "__main__":
    main()
