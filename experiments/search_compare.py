"""NSGA-II versus random search: table, comparison figure and the kept figures of each run.

    python experiments/search_compare.py out/search experiments/results/search

Reads every run directory under the first argument (each written by `adversary search`, with
its summary.json) and writes into the second: results.json, results.md, one
collisions_<planner>_<template>.png per pair (NSGA-II and random per generation, the search
paper's Fig. 10) and a copy of each run's figures and best-failure frames.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np

from riskmap.atomic import write_json

KEPT = ("collisions_per_generation.png", "best_failure_evolution.png", "pareto_front.png")


def _planner_name(spec: str) -> str:
    return "risk-map planner" if spec.startswith("riskmap") else {"idm": "IDM/MOBIL"}.get(spec, spec)


def _fmt_range(r) -> str:
    return "–" if r is None else f"{r[0]:.2f}–{r[1]:.2f}"


def compare(runs_root: Path, out: Path) -> list[dict]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for summary_path in sorted(runs_root.glob("*/summary.json")):
        s = json.loads(summary_path.read_text())
        c = s["config"]
        rows.append({"run": summary_path.parent.name, "planner": c["planner"],
                     "template": c["template"], "algorithm": c["algorithm"], "pop": c["pop"],
                     "gen": c["gen"], "evaluations": s["evaluations"], "feasible": s["feasible"],
                     "collisions": s["collisions"], "collision_share": s["collision_share"],
                     "distinct_failures": s["distinct_failures"],
                     "failure_diversity": s["failure_diversity"],
                     "collisions_per_generation": s["collisions_per_generation"],
                     "least_altered_failure": s["least_altered_failure"]})
        run_out = out / summary_path.parent.name
        run_out.mkdir(exist_ok=True)
        for name in KEPT:
            shutil.copy(summary_path.parent / name, run_out / name)
        frames = summary_path.parent / "best_failure"
        if frames.exists():
            shutil.copytree(frames, run_out / "best_failure", dirs_exist_ok=True)
        shutil.copy(summary_path, run_out / "summary.json")
    write_json(out / "results.json", rows)

    lines = [("| planner | template | algorithm | pop × gen | collisions / evaluations | share | "
              "infeasible | distinct failures | diversity range | least alteration |"),
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        best = r["least_altered_failure"]
        lines.append(
            f"| {_planner_name(r['planner'])} | {r['template']} | {r['algorithm']} | "
            f"{r['pop']} × {r['gen']} | {r['collisions']} / {r['evaluations']} | "
            f"{100 * r['collision_share']:.0f}% | {r['evaluations'] - r['feasible']} | "
            f"{r['distinct_failures']} | {_fmt_range(r['failure_diversity'])} | "
            f"{'–' if best is None else format(best['alteration'], '.2f')} |")
    (out / "results.md").write_text("\n".join(lines) + "\n")

    pairs = sorted({(r["planner"], r["template"]) for r in rows})
    for planner, template in pairs:
        fig, ax = plt.subplots(figsize=(5.5, 3.4), dpi=110)
        for r in rows:
            if (r["planner"], r["template"]) != (planner, template):
                continue
            counts = np.array(r["collisions_per_generation"])
            ax.plot(np.arange(1, len(counts) + 1), counts, "-o", ms=4,
                    label=f"{r['algorithm']} ({r['collisions']}/{r['evaluations']})")
        ax.set_xlabel("generation")
        ax.set_ylabel("collisions in the generation")
        ax.set_title(f"{_planner_name(planner)}, {template}", fontsize=9)
        ax.legend(fontsize=8)
        fig.tight_layout()
        name = "riskmap" if planner.startswith("riskmap") else planner
        fig.savefig(out / f"collisions_{name}_{template}.png")
        plt.close(fig)
    return rows


if __name__ == "__main__":
    rows = compare(Path(sys.argv[1]), Path(sys.argv[2]))
    print((Path(sys.argv[2]) / "results.md").read_text())
