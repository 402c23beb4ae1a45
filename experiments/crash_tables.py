"""CRASH on our benchmark: the paper's Table I and Table III analogues, and the cost of k.

    python experiments/crash_tables.py --part table1 --family highway [--count 100] [--workers 1]
    python experiments/crash_tables.py --part table3 --family intersection
    python experiments/crash_tables.py --part k --family highway --count 30
    python experiments/crash_tables.py --part collect       # gather every finished run into tables

Every run is an `adversary attack` run (resumable) under out/crash/<family>/<run>/ on the held-out
scenes data/attack/<family> (`adversary scenes --env ... --seed 500 --count 120`); `collect` writes
experiments/results/crash/results.json and tables.md from whatever has finished.

Table I: planners replay / IDM (rule-based, closed loop) / the risk-aware planner, each attacked
with CRASH (MAM+ASM) and with STRIVE's distance-based selection (DS).
Table III: the IDM planner with DS, DS+MAM, ASM (no MAM) and MAM+ASM, plus nearest and random.
k: the IDM planner under MAM+ASM with the planner re-run every k = 5, 20, 50, 200 iterations.
The tables re-run IDM every k = 20 iterations and the risk-aware planner every k = 50.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from adversary.crash.attack import AttackConfig
from adversary.crash.run import TABLE_HEADER, run_attacks, summarise, table_row
from riskmap.infra.atomic import atomic_write, write_json

ROOT = Path(__file__).resolve().parents[1]
PLANNERS = {"replay": "replay", "idm": "idm", "riskmap": "riskmap:checkpoints/riskmap_{family}"}
TABLE1 = [(p, s) for p in ("replay", "idm", "riskmap") for s in ("crash", "distance")]
TABLE3 = [("idm", s) for s in ("distance", "distance+mam", "crash-no-mam", "crash", "nearest", "random")]
K_VALUES = (5, 20, 50, 200)
# k per planner for the tables: a risk-aware planner rollout costs ~8x an IDM one on this CPU,
# so it is re-run every 50 iterations (the k sweep on IDM shows what that costs in success).
PLANNER_K = {"replay": 20, "idm": 20, "riskmap": 50}
LABELS = {"distance": "DS", "distance+mam": "DS+MAM", "crash-no-mam": "ASM", "crash": "MAM+ASM",
          "nearest": "nearest", "random": "random"}


def run_dir(family: str, planner: str, selector: str, k: int | None = None) -> Path:
    name = f"{planner}_{selector.replace('+', '_')}" + (f"_k{k}" if k is not None else "")
    return ROOT / "out" / "crash" / family / name


def attack(family: str, planner: str, selector: str, count: int, workers: int, k: int | None = None) -> dict:
    k = PLANNER_K[planner] if k is None else k
    spec = PLANNERS[planner].format(family=family)
    config = AttackConfig(selector=selector, replan_every=k)
    out = run_dir(family, planner, selector, k if k != 20 else None)
    return run_attacks(spec, ROOT / "data" / "attack" / family, count, config, seed=0, out=out,
                       traffic=ROOT / "checkpoints" / f"crash_traffic_{family}",
                       selectors=ROOT / "checkpoints" / f"crash_selector_{family}",
                       workers=workers, resume=True, progress=True)


def collect() -> None:
    results, lines = {}, []
    for family in ("highway", "intersection"):
        for part, runs in (("table1", [(p, s, None) for p, s in TABLE1]),
                           ("table3", [(p, s, None) for p, s in TABLE3]),
                           ("k", [("idm", "crash", k) for k in K_VALUES])):
            rows = []
            for planner, selector, swept in runs:
                k = PLANNER_K[planner] if swept is None else swept
                attacks = sorted((run_dir(family, planner, selector, k if k != 20 else None) / "attacks").glob("*.json"))
                if part == "k":        # compare k on the same scenes: those of the smallest sweep run
                    swept_names = {p.name for p in (run_dir(family, "idm", "crash", K_VALUES[0]) / "attacks").glob("*.json")}
                    attacks = [p for p in attacks if p.name in swept_names]
                if not attacks:
                    continue
                # Finished or not: every scene attacked so far counts (the table gives the denominator).
                summary = summarise([json.loads(p.read_text()) for p in attacks])
                label = f"{planner} / {LABELS[selector]}" + (f" / k={k}" if swept is not None or k != 20 else "")
                results.setdefault(family, {}).setdefault(part, {})[label] = summary
                rows.append(table_row(label, summary))
            if rows:
                lines += [f"### {family}: {part}", "", TABLE_HEADER, *rows, ""]
    out = ROOT / "experiments" / "results" / "crash"
    write_json(out / "results.json", results)
    atomic_write(out / "tables.md", lambda f: f.write("\n".join(lines).encode()))
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=("table1", "table3", "k", "collect"), required=True)
    parser.add_argument("--family", choices=("highway", "intersection"))
    parser.add_argument("--count", type=int, default=100)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--only", default="", help="comma-separated planner:selector pairs to run")
    args = parser.parse_args()
    if args.part == "collect":
        collect()
        return
    only = {tuple(x.split(":")) for x in args.only.split(",") if x}
    if args.part == "k":
        for k in K_VALUES:
            if k != PLANNER_K["idm"]:        # that one is the table run itself (a superset)
                attack(args.family, "idm", "crash", args.count, args.workers, k)
        return
    for planner, selector in TABLE1 if args.part == "table1" else TABLE3:
        if only and (planner, selector) not in only:
            continue
        attack(args.family, planner, selector, args.count, args.workers)


if __name__ == "__main__":
    main()
