"""Choose a checkpoint's planning-time goal variance on held-out windows and record it in its sidecar.

The goal enters value iteration as −d²/(2σ²) (cells) against per-cell rewards of about −1 to −2,
so the trained σ² = 5 lets plans stop ~8 cells short of the goal (riskmap/planner/riskmap_planner.py,
`RiskMapPlanner.load`). This script plans every candidate σ² on the same held-out windows and
writes the one with the lowest mean ADE against the recorded future into the sidecar's
`planning` section, with the evidence, so that `riskmap:PATH` plans with it from then on.

    .venv/bin/python experiments/tune_goal_variance.py --checkpoint checkpoints/riskmap_highway \
        --data data/highway_heldout --candidates 5,2,1,0.5 --limit 60 [--dry-run]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from eval_plans import evaluate

from riskmap.infra.atomic import write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, required=True)
    parser.add_argument("--data", type=Path, required=True, help="held-out windows (not training)")
    parser.add_argument("--candidates", default="5,2,1,0.5", help="goal variances, cells²")
    parser.add_argument("--limit", type=int, default=60, help="windows, evenly spread")
    parser.add_argument("--dry-run", action="store_true", help="print, do not write the sidecar")
    args = parser.parse_args()
    weights = args.checkpoint.with_suffix(".safetensors")
    rows = []
    for variance in (float(v) for v in args.candidates.split(",")):
        r = evaluate(weights, args.data, args.limit, goal_variance=variance)
        rows.append({"goal_variance": variance, "windows": r["windows"],
                     "ade_m": r["ade_m"]["mean"], "fde_m": r["fde_m"]["mean"],
                     "goal_error_m": r["goal_error_m"]["mean"],
                     "end_short_of_demo_m": r["end_short_of_demo_m"]["mean"]})
        print(" ".join(f"{k}={v:.2f}" if isinstance(v, float) else f"{k}={v}"
                       for k, v in rows[-1].items()), flush=True)
    best = min(rows, key=lambda row: row["ade_m"])
    print(f"chosen goal variance {best['goal_variance']:g} (lowest mean ADE {best['ade_m']:.2f} m)")
    if not args.dry_run:
        sidecar = args.checkpoint.with_suffix(".json")
        data = json.loads(sidecar.read_text())
        data["planning"] = {"goal_variance": best["goal_variance"], "chosen_by": "lowest mean ADE",
                            "held_out_data": str(args.data), "candidates": rows}
        write_json(sidecar, data)
        print(f"wrote planning.goal_variance to {sidecar}")


if __name__ == "__main__":
    main()
