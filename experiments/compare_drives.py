"""Side-by-side table of `riskmap drive` runs (collision rate, progress, gaps, planning time).

    .venv/bin/python experiments/compare_drives.py out/eval/highway/idm out/eval/highway/riskmap ...
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def load(run: Path) -> dict:
    records = [json.loads(p.read_text()) for p in sorted((run / "episodes").glob("*.json"))]
    meta = json.loads((run / "run.json").read_text())
    collided = np.array([r["collided"] for r in records], dtype=float)
    return {
        "run": str(run), "planner": meta["planner"], "env": meta["config"]["env_id"],
        "episodes": len(records), "collisions": int(collided.sum()),
        "collision_rate": float(collided.mean()),
        "off_road": int(sum(r["off_road"] for r in records)),
        "distance_m": float(np.mean([r["distance_m"] for r in records])),
        "mean_speed_mps": float(np.mean([r["mean_speed_mps"] for r in records])),
        "min_gap_m": float(np.mean([100.0 if r["min_gap_m"] is None else min(r["min_gap_m"], 100.0)
                                         for r in records])),
        "plan_ms_median": (float(np.median([r["plan_ms_median"] for r in records]))
                           if records[0]["plan_ms_median"] is not None else None),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--out", type=Path, default=None, help="also write the rows as JSON")
    args = parser.parse_args()
    rows = [load(r) for r in args.runs]
    print("| env | planner | episodes | collisions | collision rate | off-road | distance (m) | "
          "mean speed (m/s) | mean min gap (m, capped 100) | plan ms (median) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        ms = f"{r['plan_ms_median']:.0f}" if r["plan_ms_median"] is not None else "-"
        print(f"| {r['env']} | {r['planner']} | {r['episodes']} | {r['collisions']} | "
              f"{100 * r['collision_rate']:.1f}% | {r['off_road']} | {r['distance_m']:.0f} | "
              f"{r['mean_speed_mps']:.1f} | {r['min_gap_m']:.1f} | {ms} |")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
