"""NSGA-II versus random search: table, comparison figure and the kept figures of each run.

    python experiments/search_compare.py experiments/results/search out/search [more roots...]

Reads every run directory under the roots (each written by `adversary search`, with its
summary.json) and writes into the first argument: results.json, results.md, one
collisions_<planner>_<template>_<pop>x<gen>.png per pair (NSGA-II and random per generation,
the search paper's Fig. 10), a copy of each run's figures, and three frames of each planner's
least-altered failure over all runs.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np

from riskmap.infra.atomic import write_json

KEPT = ("collisions_per_generation.png", "best_failure_evolution.png", "pareto_front.png")


def _planner_name(spec: str) -> str:
    return "risk-map planner" if spec.startswith("riskmap") else {"idm": "IDM/MOBIL"}.get(spec, spec)


def _fmt_range(r) -> str:
    return "–" if r is None else f"{r[0]:.2f}–{r[1]:.2f}"


def compare(roots: list[Path], out: Path) -> list[dict]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for summary_path in sorted(p for root in roots for p in root.glob("*/summary.json")):
        s = json.loads(summary_path.read_text())
        c = s["config"]
        run = f"{summary_path.parent.name}_{c['pop']}x{c['gen']}"
        rows.append({"run": run, "planner": c["planner"],
                     "template": c["template"], "algorithm": c["algorithm"], "pop": c["pop"],
                     "gen": c["gen"], "evaluations": s["evaluations"], "feasible": s["feasible"],
                     "collisions": s["collisions"], "collision_share": s["collision_share"],
                     "distinct_failures": s["distinct_failures"],
                     "failure_diversity": s["failure_diversity"],
                     "collisions_per_generation": s["collisions_per_generation"],
                     "least_altered_failure": s["least_altered_failure"]})
        run_out = out / run
        run_out.mkdir(exist_ok=True)
        for name in KEPT:
            shutil.copy(summary_path.parent / name, run_out / name)
        shutil.copy(summary_path, run_out / "summary.json")
        rows[-1]["path"] = summary_path.parent
    rows.sort(key=lambda r: (r["planner"], r["template"], r["pop"], r["algorithm"]))
    # Frames of each planner's least-altered failure over all runs (kept small: the start, one
    # second before the end, and the last step).
    for planner in sorted({r["planner"] for r in rows}):
        failing = [r for r in rows if r["planner"] == planner and r["least_altered_failure"]]
        if not failing:
            continue
        best = min(failing, key=lambda r: r["least_altered_failure"]["alteration"])
        frames = sorted((best["path"] / "best_failure").glob("frame_*.png"))
        if frames:
            (out / best["run"] / "best_failure").mkdir(exist_ok=True)
            for frame in {frames[0], frames[max(0, len(frames) - 2)], frames[-1]}:
                shutil.copy(frame, out / best["run"] / "best_failure" / frame.name)
    for r in rows:
        del r["path"]
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

    pairs = sorted({(r["planner"], r["template"], r["pop"], r["gen"]) for r in rows})
    for planner, template, pop, gen in pairs:
        fig, ax = plt.subplots(figsize=(5.5, 3.4), dpi=110)
        for r in rows:
            if (r["planner"], r["template"], r["pop"], r["gen"]) != (planner, template, pop, gen):
                continue
            counts = np.array(r["collisions_per_generation"])
            ax.plot(np.arange(1, len(counts) + 1), counts, "-o", ms=4,
                    label=f"{r['algorithm']} ({r['collisions']}/{r['evaluations']})")
        ax.set_xlabel("generation")
        ax.set_ylabel("collisions in the generation")
        ax.set_title(f"{_planner_name(planner)}, {template}, pop {pop} × {gen} generations",
                     fontsize=9)
        ax.legend(fontsize=8)
        fig.tight_layout()
        name = "riskmap" if planner.startswith("riskmap") else planner
        fig.savefig(out / f"collisions_{name}_{template}_{pop}x{gen}.png")
        plt.close(fig)
    return rows


if __name__ == "__main__":
    rows = compare([Path(a) for a in sys.argv[2:]], Path(sys.argv[1]))
    print((Path(sys.argv[1]) / "results.md").read_text())
