"""Uncertainty weight v at four levels (planner paper Fig. 5 analogue): overlap, gap, progress, collisions.

Each level is a run trained on the same 640 highway windows with the same seed for 2 epochs:

    riskmap train --data data/highway --out runs/highway_v{V} --epochs 2 --lr 5e-4 \
        --uncertainty-weight V --max-windows 640 --seed 0          # V in 0 1 3 10

Then per level: the mean share of the policy's expected visits on the agents' uncertainty map N
over held-out windows (open loop), and closed loop on 10 held-out highway seeds (`riskmap drive`,
reused from OUT_ROOT/v{V} when already driven): mean minimum gap, distance, collisions.
Writes experiments/results/ablation_uncertainty_weight/{results.json,table.md,ablation.png}.

    .venv/bin/python experiments/ablation_uncertainty_weight.py --levels 0 1 3 10
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from riskmap.evaluation.drive import drive
from riskmap.evaluation.open_loop import evaluate
from riskmap.figures.ablation import print_row, pyplot, save_figure, write_table
from riskmap.infra.atomic import write_json
from riskmap.sim.worlds.highway_drive import DriveConfig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", nargs="+", default=["0", "1", "3", "10"])
    parser.add_argument("--runs", default="runs/highway_v{}", help="run directory per level")
    parser.add_argument("--heldout", type=Path, default=Path("data/highway_heldout"))
    parser.add_argument("--windows", type=int, default=60)
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--drive-root", type=Path, default=Path("out/eval/highway"))
    parser.add_argument("--out", type=Path, default=Path("experiments/results/ablation_uncertainty_weight"))
    args = parser.parse_args()
    rows = []
    for level in args.levels:
        checkpoint = Path(args.runs.format(level)) / "last"
        open_loop = evaluate(checkpoint.with_suffix(".safetensors"), args.heldout, args.windows)
        summary = drive(DriveConfig("highway-v0", args.episodes, seed=0), f"riskmap:{checkpoint}",
                        args.drive_root / f"v{level}", resume=True, progress=False)["summary"]
        rows.append({"v": float(level), "checkpoint": str(checkpoint),
                     "svf_overlap": open_loop["svf_uncertainty_overlap"]["mean"],
                     "ade_m": open_loop["ade_m"]["mean"], "episodes": summary["episodes"],
                     "min_gap_m": summary["min_gap_m"], "distance_m": summary["distance_m"],
                     "collision_rate": summary["collision_rate"]})
        print_row(rows[-1])
    write_json(args.out / "results.json", {"rows": rows, "heldout": str(args.heldout),
                                           "windows": args.windows})
    lines = ["| v | SVF overlap with N | ADE (m) | episodes | mean min gap (m) | distance (m) | collisions |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['v']:g} | {r['svf_overlap']:.4f} | {r['ade_m']:.2f} | {r['episodes']} | "
                     f"{r['min_gap_m']:.1f} | {r['distance_m']:.0f} | "
                     f"{round(r['collision_rate'] * r['episodes'])} / {r['episodes']} |")
    write_table(args.out, lines)

    plt = pyplot()
    v = np.array([r["v"] for r in rows])
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 3.2), dpi=110)
    for ax, key, label in zip(axes, ("svf_overlap", "min_gap_m", "distance_m"),
                              ("SVF overlap with N (open loop)", "mean min gap (m, closed loop)",
                               "distance (m, closed loop)"), strict=True):
        ax.plot(np.arange(len(v)), [r[key] for r in rows], "-o")
        ax.set_xticks(np.arange(len(v)), [f"{x:g}" for x in v])
        ax.set_xlabel("uncertainty weight v")
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
    save_figure(fig, args.out, "uncertainty weight ablation, highway (same data and seed per level)")


if __name__ == "__main__":
    main()
