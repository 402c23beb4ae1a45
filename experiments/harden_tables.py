"""The hardening loop on our benchmark: every round of `adversary harden` runs and the NSGA-II
search at equal budget, before and after.

    python experiments/harden_tables.py --run highway=runs/harden/highway --run us101=runs/harden/us101 \
        --search original=out/harden_search/original --search hardened=out/harden_search/hardened

`--run FAMILY=DIR`: an `adversary harden --out` directory (its rounds.json and report PNGs);
`--search LABEL=DIR`: a directory holding `adversary search --out` runs (one per template);
`--attack LABEL=DIR`: an `adversary attack --out` run (a fresh attack on more held-out scenes).
Writes experiments/results/harden/results.json and tables.md (95% Wilson intervals) and copies
each run's before/after panels next to them.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from adversary.harden.report import COLUMNS, round_row
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.stats import wilson

ROOT = Path(__file__).resolve().parents[1]


def _pairs(values: list[str], flag: str) -> dict[str, Path]:
    out = {}
    for value in values:
        label, _, path = value.partition("=")
        if not label or not path:
            raise SystemExit(f"{flag} {value!r}: write LABEL=DIR")
        out[label] = Path(path)
    return out


def search_rows(label: str, root: Path) -> list[dict]:
    rows = []
    for summary in sorted(root.glob("*/summary.json")):
        s = json.loads(summary.read_text())
        cfg = s["config"]
        ci = wilson(s["collisions"], s["evaluations"])
        rows.append({"planner": label, "spec": cfg["planner"], "template": cfg["template"],
                     "budget": f"{cfg['pop']} x {cfg['gen']}", "collisions": s["collisions"],
                     "evaluations": s["evaluations"], "share": s["collision_share"],
                     "ci95": [ci["lo"], ci["hi"]]})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", action="append", default=[], help="FAMILY=DIR of an adversary harden run")
    parser.add_argument("--search", action="append", default=[], help="LABEL=DIR of adversary search runs")
    parser.add_argument("--attack", action="append", default=[], help="LABEL=DIR of an adversary attack run")
    parser.add_argument("--out", default=str(ROOT / "experiments/results/harden"))
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict = {"runs": {}, "search": [], "attacks": {}}
    lines = []
    for family, run in _pairs(args.run, "--run").items():
        rounds = json.loads((run / "rounds.json").read_text())["rounds"]
        settings = json.loads((run / "harden.json").read_text())
        results["runs"][family] = {"settings": {k: v for k, v in settings.items() if k != "git_commit"},
                                   "rounds": rounds}
        lines += [f"### {family}: `{settings['checkpoint']}`", "", "| " + " | ".join(COLUMNS) + " |",
                  "|" + "---|" * len(COLUMNS)]
        lines += ["| " + " | ".join(round_row(e)) + " |" for e in rounds]
        lines.append("")
        for png in sorted((run / "report").glob("before_after_round_*.png")):
            shutil.copyfile(png, out / f"{family}_{png.name}")
    attacks = _pairs(args.attack, "--attack")
    if attacks:
        lines += ["### Fresh CRASH (MAM+ASM) on more held-out scenes", "",
                  "| planner | collisions / scenes (95% CI) |", "|---|---|"]
    for label, root in attacks.items():
        s = json.loads((root / "summary.json").read_text())
        results["attacks"][label] = {k: s[k] for k in ("planner", "scenes", "count")} | {"summary": s["summary"]}
        lo, hi = s["summary"]["collision_ci95"]
        lines.append(f"| {label} (`{s['planner']}`) | {s['summary']['collisions']}/{s['summary']['scenes']} "
                     f"({100 * s['summary']['collision_rate']:.0f}% [{100 * lo:.0f}–{100 * hi:.0f}]) |")
    if attacks:
        lines.append("")
    for label, root in _pairs(args.search, "--search").items():
        results["search"] += search_rows(label, root)
    if results["search"]:
        lines += ["### NSGA-II search at equal budget", "",
                  "| planner | template | pop x gen | collisions / evaluations (share, 95% CI) |", "|---|---|---|---|"]
        lines += [f"| {r['planner']} (`{r['spec']}`) | {r['template']} | {r['budget']} | {r['collisions']}/"
                  f"{r['evaluations']} ({100 * r['share']:.0f}% [{100 * r['ci95'][0]:.0f}–{100 * r['ci95'][1]:.0f}]) |"
                  for r in results["search"]]
    write_json(out / "results.json", results)
    atomic_write(out / "tables.md", lambda f: f.write(("\n".join(lines) + "\n").encode()))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
