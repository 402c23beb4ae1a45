"""Grid resolution 25/50/75/100: value-iteration and total plan time per call vs ADE and goal error
(planner paper Fig. 3f analogue).

One run per resolution, same 640 highway windows, seed, v = 1 and 2 epochs:

    riskmap train --data data/highway --out runs/highway_r{G} --resolution G --epochs 2 --lr 5e-4 \
        --uncertainty-weight 1 --max-windows 640 --seed 0          # G in 25 75 100; 50 = runs/highway_v1

Each plans the same held-out windows (batch 1, torch with --threads threads); medians of the
per-stage timings, means of ADE and goal error. Writes experiments/results/ablation_resolution/.

    .venv/bin/python experiments/ablation_resolution.py [--windows 60]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from riskmap.data.dataset import DemoDataset
from riskmap.evaluation.open_loop import window_errors
from riskmap.figures.ablation import print_row, pyplot, save_figure, write_table
from riskmap.infra.atomic import write_json
from riskmap.planner.riskmap_planner import RiskMapPlanner

RUNS = {25: "runs/highway_r25", 50: "runs/highway_v1", 75: "runs/highway_r75", 100: "runs/highway_r100"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--heldout", type=Path, default=Path("data/highway_heldout"))
    parser.add_argument("--windows", type=int, default=60)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("experiments/results/ablation_resolution"))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    rows = []
    for g, run in RUNS.items():
        if not (Path(run) / "last.safetensors").exists():
            print(f"resolution {g}: no run at {run}; train it first (see the docstring)", flush=True)
            continue
        planner = RiskMapPlanner.load(Path(run) / "last")
        dataset = DemoDataset(args.heldout, planner.grid.rows, raster=planner.raster)
        picks = np.unique(np.linspace(0, len(dataset) - 1, args.windows).astype(int))
        side = json.loads((Path(run) / "last.json").read_text())["maps"]
        e = window_errors(planner, dataset, picks, side["sigma_x"], side["sigma_y"])
        rows.append({"resolution": g, "horizon": planner.horizon, "windows": len(picks),
                     "ade_m": float(np.mean(e["ade_m"])), "goal_error_m": float(np.mean(e["goal_error_m"])),
                     "vi_ms": float(np.median(e["vi_ms"])), "total_ms": float(np.median(e["plan_ms"]))})
        print_row(rows[-1])
    write_json(args.out / "results.json", {"rows": rows, "runs": RUNS, "threads": args.threads})
    lines = ["| resolution | horizon | windows | ADE (m) | goal error (m) | VI ms | plan ms |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['resolution']} | {r['horizon']} | {r['windows']} | {r['ade_m']:.2f} | "
              f"{r['goal_error_m']:.2f} | {r['vi_ms']:.1f} | {r['total_ms']:.1f} |" for r in rows]
    write_table(args.out, lines)

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(8.5, 3.3), dpi=110)
    g = [r["resolution"] for r in rows]
    axes[0].plot(g, [r["vi_ms"] for r in rows], "-o", label="value iteration")
    axes[0].plot(g, [r["total_ms"] for r in rows], "-s", label="whole plan")
    axes[0].set_ylabel("ms per call (median)")
    axes[0].legend(fontsize=8)
    axes[1].plot(g, [r["ade_m"] for r in rows], "-o", label="ADE")
    axes[1].plot(g, [r["goal_error_m"] for r in rows], "-s", label="goal error")
    axes[1].set_ylabel("m (mean over held-out windows)")
    axes[1].legend(fontsize=8)
    for ax in axes:
        ax.set_xlabel("grid resolution (cells a side)")
        ax.set_xticks(g)
        ax.grid(alpha=0.3)
    save_figure(fig, args.out, "resolution ablation, highway (same data, seed and training per resolution)")


if __name__ == "__main__":
    main()
