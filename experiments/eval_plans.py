"""Open-loop plan quality of checkpoints on held-out windows (riskmap.evaluation.open_loop):
writes a JSON per checkpoint into --out and prints a table.

    .venv/bin/python experiments/eval_plans.py --data data/highway_heldout \
        --checkpoints checkpoints/highway.safetensors [more ...] --out experiments/results/plans
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from riskmap.evaluation.open_loop import evaluate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--checkpoints", type=Path, nargs="+", required=True)
    parser.add_argument("--limit", type=int, default=None, help="evaluate this many windows")
    parser.add_argument("--goal-variance", type=float, default=None,
                        help="cells²; override the checkpoint's goal variance at planning time")
    parser.add_argument("--out", type=Path, default=Path("experiments/results/plans"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{'checkpoint':40s} {'v':>5s} {'windows':>7s} {'ADE':>6s} {'FDE':>6s} {'goal':>6s} "
          f"{'overlap':>8s} {'short':>6s}")
    for ckpt in args.checkpoints:
        r = evaluate(ckpt, args.data, args.limit, goal_variance=args.goal_variance)
        suffix = "" if args.goal_variance is None else f"_gv{args.goal_variance:g}"
        name = f"{ckpt.parent.name}_{ckpt.stem}_{args.data.name}{suffix}.json"
        (args.out / name).write_text(json.dumps(r, indent=2) + "\n")
        print(f"{str(ckpt):40s} {r['uncertainty_weight']:5.1f} {r['windows']:7d} "
              f"{r['ade_m']['mean']:6.2f} {r['fde_m']['mean']:6.2f} {r['goal_error_m']['mean']:6.2f} "
              f"{r['svf_uncertainty_overlap']['mean']:8.4f} {r['end_short_of_demo_m']['mean']:6.1f}")


if __name__ == "__main__":
    main()
