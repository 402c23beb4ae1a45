"""Plan latency and plans of the space-time planner: a reference commit's code against this tree's,
in one process, on the same scenes.

The reference commit's `riskmap` and `rasterize` packages are extracted (`git archive`) into a
temporary folder and imported under their own names beside this tree's (each planner's modules
are put back in `sys.modules` around its calls, so that imports made at call time resolve to its
own tree). Both planners load the same checkpoint and plan the same highway-v0 moments of
`bench_planner.py` (2 s of history), interleaved call by call, so that both see the same machine
state; medians per stage over `--calls` plans after `--warmup`, and the ratio reference ÷ now
(above 1: faster now). "total" is the time to the waypoints (raster and evidence, network, value
iteration with the planning-time penalties, sampler).

Equivalence (`--data`, `--windows`): both plan the same windows of a recorded dataset (evenly
spread) with the same seed; reported are the largest waypoint difference (m), the share of
windows whose waypoints agree to 1e-6 m, the largest difference of the reward maps r_1 … r_T and
of the goal map, and the mean ADE of each against the recorded future.

    .venv/bin/python experiments/bench_st_latency_ab.py [--reference HEAD] \
        [--checkpoint checkpoints/riskmap_st_highway] [--calls 40] [--threads 1] \
        [--data data/highway --windows 200] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import platform
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("riskmap", "rasterize")
STAGES = ("raster", "network", "vi", "sampler", "total")


def _ours(name: str) -> bool:
    return name.split(".")[0] in PACKAGES


class Tree:
    """One tree's `riskmap` and `rasterize` modules, imported from `path` first on sys.path."""

    def __init__(self, path: Path):
        self.path = path
        saved = {n: m for n, m in sys.modules.items() if _ours(n)}
        for name in saved:
            del sys.modules[name]
        sys.path.insert(0, str(path))
        try:
            importlib.invalidate_caches()
            self.load_planner = importlib.import_module("riskmap.planner.riskmap_planner").load_planner
            importlib.import_module("riskmap.planner.st_planner")
            self.modules = {n: m for n, m in sys.modules.items() if _ours(n)}
        finally:
            sys.path.remove(str(path))
            for name in [n for n in sys.modules if _ours(n)]:
                del sys.modules[name]
            sys.modules.update(saved)
        origin = Path(self.modules["riskmap"].__file__).resolve().parents[1]
        if origin != path.resolve():
            raise SystemExit(f"bench: riskmap came from {origin}, not {path}")

    @contextlib.contextmanager
    def active(self):
        saved = {n: m for n, m in sys.modules.items() if _ours(n)}
        for name in saved:
            del sys.modules[name]
        sys.modules.update(self.modules)
        sys.path.insert(0, str(self.path))
        try:
            yield
        finally:
            sys.path.remove(str(self.path))
            for name in [n for n in sys.modules if _ours(n)]:
                del sys.modules[name]
            sys.modules.update(saved)


def extract(commit: str, into: Path) -> Path:
    archive = subprocess.run(["git", "archive", "--format=tar", commit, *PACKAGES], cwd=ROOT,
                             check=True, capture_output=True).stdout
    with tarfile.open(fileobj=BytesIO(archive)) as tar:
        tar.extractall(into, filter="data")
    return into


def latency(trees: dict, planners: dict, scenes: list, calls: int, warmup: int) -> dict:
    times = {name: {stage: [] for stage in STAGES} for name in planners}
    for call in range(warmup + calls):
        scene = scenes[call % len(scenes)]
        order = list(planners) if call % 2 == 0 else list(planners)[::-1]
        for name in order:
            with trees[name].active():
                plan = planners[name].plan(scene)
            if call >= warmup:
                for stage in STAGES:
                    times[name][stage].append(plan.timings_s[stage])
    return {name: {stage: 1000 * statistics.median(v) for stage, v in stages.items()}
            for name, stages in times.items()}


def equivalence(trees: dict, planners: dict, data: str, windows: int) -> dict:
    import numpy as np

    from rasterize.frames import ego_from_world, ego_pose
    from riskmap.data.dataset import DemoDataset

    first = planners["now"]
    dataset = DemoDataset(data, first.grid.rows, raster=first.raster)
    picks = np.unique(np.linspace(0, len(dataset) - 1, windows).astype(int))
    for name, planner in planners.items():
        with trees[name].active():
            planner.reset(None)
    gaps, reward_gaps, goal_gaps, ade = [], [], [], {name: [] for name in planners}
    for i in picks:
        scene = dataset.scene(int(i))
        origin, heading = ego_pose(scene)
        demo = ego_from_world(scene.ego_future_xy(), origin, heading)
        plans = {}
        for name, planner in planners.items():
            with trees[name].active():
                plans[name] = planner.plan(scene)
            ade[name].append(float(np.linalg.norm(plans[name].waypoints - demo, axis=1).mean()))
        ref, now = plans.values()
        gaps.append(float(np.abs(ref.waypoints - now.waypoints).max()))
        reward_gaps.append(float(np.abs(ref.risk_steps - now.risk_steps).max()))
        goal_gaps.append(float(np.abs(np.log(ref.goal_map) - np.log(now.goal_map)).max()))
    gaps = np.array(gaps)
    return {"data": data, "windows": len(picks), "waypoint_gap_m_max": float(gaps.max()),
            "waypoints_equal_1e-6": float((gaps <= 1e-6).mean()),
            "windows_differing": int((gaps > 1e-6).sum()),
            "reward_gap_max": max(reward_gaps), "goal_log_gap_max": max(goal_gaps),
            "ade_m": {name: float(np.mean(v)) for name, v in ade.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", default="HEAD", help="the commit to compare against")
    parser.add_argument("--checkpoint", default="checkpoints/riskmap_st_highway")
    parser.add_argument("--calls", type=int, default=40)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--data", help="a recorded dataset to compare plans on (equivalence)")
    parser.add_argument("--windows", type=int, default=200)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    import torch

    torch.set_num_threads(args.threads)
    sys.meta_path[:] = [f for f in sys.meta_path
                        if "__editable__" not in getattr(f, "__module__", "")]
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    commit = subprocess.run(["git", "rev-parse", "--short", args.reference], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout.strip()
    result = {"reference": commit, "checkpoint": args.checkpoint, "threads": args.threads,
              "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
              "torch": torch.__version__}
    with tempfile.TemporaryDirectory(prefix="st_ref_") as tmp:
        trees = {"reference": Tree(extract(commit, Path(tmp))), "now": Tree(ROOT)}
        sys.path.insert(0, str(ROOT))                # everything else: this tree
        sys.modules.update(trees["now"].modules)
        planners = {}
        for name, tree in trees.items():
            with tree.active():
                planners[name] = tree.load_planner(args.checkpoint)
        if args.calls:
            from bench_planner import highway_scenes

            started = time.perf_counter()
            medians = latency(trees, planners, highway_scenes(8), args.calls, args.warmup)
            result.update(calls=args.calls, medians_ms=medians,
                          ratio_reference_over_now={s: medians["reference"][s] / medians["now"][s]
                                                    for s in STAGES})
            print(f"{'tree':<10} " + " ".join(f"{s + ' ms':>11}" for s in STAGES))
            for name, row in medians.items():
                print(f"{name:<10} " + " ".join(f"{row[s]:11.1f}" for s in STAGES))
            print(f"{'ref / now':<10} " + " ".join(
                f"{result['ratio_reference_over_now'][s]:10.2f}x" for s in STAGES)
                + f"   ({time.perf_counter() - started:.0f} s)", flush=True)
        if args.data:
            result["equivalence"] = equivalence(trees, planners, args.data, args.windows)
            print(json.dumps(result["equivalence"]), flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
