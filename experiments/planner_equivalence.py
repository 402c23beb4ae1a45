"""Plans of this tree's planner against an earlier commit's, on the same held-out windows.

The earlier planner is rebuilt in this process from `--commit`'s `riskmap/planner/vi.py` and
`riskmap/planner/sampler.py` (git show) with the network as loaded (no `for_inference`); the
current one is `RiskMapPlanner.load` as shipped. Both plan every window (evenly spread,
`--windows` per dataset) with the same seed; reported per checkpoint: the share of windows whose
waypoints agree to 1e-6 m, mean ADE / FDE against the recorded future (`window_errors`, the
metric of `riskmap evaluate-open-loop`) with the paired difference and its 95% bootstrap
interval, and the median plan time of each. The noise to judge a difference by: the earlier
planner against itself with another planner seed (`--noise-seed`), the same windows.

    .venv/bin/python experiments/planner_equivalence.py --commit a77ace6 \
        --pair checkpoints/riskmap_highway=data/highway_heldout \
        --pair checkpoints/riskmap_intersection=data/intersection_heldout [--windows 300]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

import numpy as np
import torch
from bench_against_commit import module_at

import riskmap.planner.riskmap_planner as planner_module
from riskmap.data.dataset import DemoDataset
from riskmap.evaluation.open_loop import window_errors
from riskmap.infra.checkpoint import read_sidecar
from riskmap.planner.model import load_model
from riskmap.planner.riskmap_planner import RiskMapPlanner


def earlier_planner(checkpoint: str, sampler_then, seed: int = 0) -> RiskMapPlanner:
    """The shipped planner with the earlier commit's sampler settings and the network exactly as
    trained (batch norms, default layout); `plans_with` swaps in its VI, SVF and sampler."""
    planner = RiskMapPlanner.load(checkpoint, seed=seed)
    planner.model, _ = load_model(Path(checkpoint))
    planner.model.eval()
    planner.sampler = sampler_then.SamplerConfig(**vars(planner.sampler))
    return planner


def plans_with(planner, dataset, picks, sx, sy, vi_fns=None, sample_fn=None) -> tuple[dict, list]:
    """window_errors of `planner`, with the module's VI/SVF and sampler swapped for the call."""
    saved = (planner_module.soft_value_iteration, planner_module.state_visitation,
             planner_module.sample_trajectory)
    waypoints = []
    original_plan = planner.plan

    def recording_plan(scene):
        plan = original_plan(scene)
        waypoints.append(plan.waypoints)
        return plan

    try:
        if vi_fns:
            planner_module.soft_value_iteration, planner_module.state_visitation = vi_fns
        if sample_fn:
            planner_module.sample_trajectory = sample_fn
        planner.plan = recording_plan
        errors = window_errors(planner, dataset, picks, sx, sy)
    finally:
        (planner_module.soft_value_iteration, planner_module.state_visitation,
         planner_module.sample_trajectory) = saved
        planner.plan = original_plan
    return errors, waypoints


def bootstrap_mean(diff: np.ndarray, rng: np.random.Generator, draws: int = 4000) -> list[float]:
    means = diff[rng.integers(0, len(diff), (draws, len(diff)))].mean(axis=1)
    return [float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commit", required=True, help="the earlier commit (its planner files)")
    parser.add_argument("--pair", action="append", required=True, metavar="CHECKPOINT=DATA",
                        help="a checkpoint and a held-out dataset of its family (repeatable)")
    parser.add_argument("--windows", type=int, default=300)
    parser.add_argument("--noise-seed", type=int, default=1)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path,
                        default=Path("experiments/results/planner_equivalence.json"))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        vi_then = module_at(args.commit, "riskmap/planner/vi.py", "vi_then", Path(tmp))
        sampler_then = module_at(args.commit, "riskmap/planner/sampler.py", "sampler_then", Path(tmp))
    rng = np.random.default_rng(0)
    rows = []
    for pair in args.pair:
        checkpoint, data = pair.split("=", 1)
        side = read_sidecar(Path(checkpoint))
        sx, sy = side["maps"]["sigma_x"], side["maps"]["sigma_y"]
        now = RiskMapPlanner.load(checkpoint)
        dataset = DemoDataset(data, now.grid.rows, raster=now.raster)
        picks = np.unique(np.linspace(0, len(dataset) - 1, args.windows).astype(int))
        swapped = ((vi_then.soft_value_iteration, vi_then.state_visitation),
                   sampler_then.sample_trajectory)
        e_then, w_then = plans_with(earlier_planner(checkpoint, sampler_then), dataset, picks,
                                    sx, sy, *swapped)
        e_noise, _ = plans_with(earlier_planner(checkpoint, sampler_then, args.noise_seed),
                                dataset, picks, sx, sy, *swapped)
        e_now, w_now = plans_with(now, dataset, picks, sx, sy)
        gap = np.array([np.abs(a - b).max() for a, b in zip(w_then, w_now, strict=True)])
        row = {"checkpoint": checkpoint, "data": data, "windows": len(picks),
               "waypoints_equal_1e-6": float((gap <= 1e-6).mean()),
               "waypoint_gap_m_median": float(np.median(gap))}
        for key in ("ade_m", "fde_m"):
            a, b = np.array(e_then[key]), np.array(e_now[key])
            row[f"{key}_then"], row[f"{key}_now"] = float(a.mean()), float(b.mean())
            row[f"{key}_diff"] = float((b - a).mean())
            row[f"{key}_diff_ci95"] = bootstrap_mean(b - a, rng)
            noise = np.array(e_noise[key]) - a
            row[f"{key}_seed_noise"] = float(noise.mean())
            row[f"{key}_seed_noise_ci95"] = bootstrap_mean(noise, rng)
        row["plan_ms_then"] = statistics.median(e_then["plan_ms"])
        row["plan_ms_now"] = statistics.median(e_now["plan_ms"])
        rows.append(row)
        print(json.dumps(row), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"commit": args.commit, "rows": rows}, indent=2) + "\n")


if __name__ == "__main__":
    main()
