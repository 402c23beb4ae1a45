"""The hardening loop on our benchmark: every round of `adversary harden` runs and the NSGA-II
search at equal budget, before and after.

    python experiments/harden_tables.py --run highway=runs/harden/highway --run us101=runs/harden/us101 \
        --search original=out/harden_search/original --search hardened=out/harden_search/hardened

`--run FAMILY=DIR`: an `adversary harden --out` directory (its rounds.json and report PNGs);
`--search LABEL=DIR`: a directory holding `adversary search --out` runs (one per template);
`--attack LABEL=DIR`: an `adversary attack --out` run (a fresh attack on more held-out scenes);
`--natural LABEL=DIR`: a `riskmap evaluate --out` run of one planner (natural traffic, closed
loop), and `--ade LABEL=FILE` an open-loop ADE record (`riskmap.evaluation.open_loop.evaluate`'s,
as a hardening round writes it: `ade.json`), both shown beside the attack of the same label;
`--paired A:B`: the two attacks' outcomes paired
on their common scenes, with a two-sided sign test.
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
from riskmap.infra.stats import sign_test, wilson

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
        # failures that count (valid, avoidable, at fault: riskmap.sim.records.failures); searches
        # written before the classification have none
        counted = (s.get("failures") or {}).get("counted")
        counted_ci = wilson(counted, s["evaluations"]) if counted is not None else None
        rows.append({"planner": label, "spec": cfg["planner"], "template": cfg["template"],
                     "budget": f"{cfg['pop']} x {cfg['gen']}", "collisions": s["collisions"],
                     "evaluations": s["evaluations"], "share": s["collision_share"],
                     "ci95": [ci["lo"], ci["hi"]], "counted": counted,
                     "counted_ci95": [counted_ci["lo"], counted_ci["hi"]] if counted_ci else None})
    return rows


def _share(k: int | None, n: int, ci: list[float] | None) -> str:
    if k is None:
        return "–"
    return f"{k}/{n} ({100 * k / n:.0f}% [{100 * ci[0]:.0f}–{100 * ci[1]:.0f}])"


def outcomes(attack_run: Path) -> dict[str, bool]:
    """Scene name → whether the attack collided, for every scene an `adversary attack` run judged."""
    return {path.stem: bool(json.loads(path.read_text())["collision"])
            for path in sorted((attack_run / "attacks").glob("scene_*.json"))}


def paired(a: Path, b: Path) -> dict:
    """Two attack runs on their common scenes: counts won against one planner only, and the
    two-sided sign test over the scenes that differ."""
    x, y = outcomes(a), outcomes(b)
    common = sorted(set(x) & set(y))
    a_only = sum(x[s] and not y[s] for s in common)
    b_only = sum(y[s] and not x[s] for s in common)
    return {"scenes": len(common), "a_only": a_only, "b_only": b_only, "p": sign_test(a_only, b_only)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", action="append", default=[], help="FAMILY=DIR of an adversary harden run")
    parser.add_argument("--search", action="append", default=[], help="LABEL=DIR of adversary search runs")
    parser.add_argument("--attack", action="append", default=[], help="LABEL=DIR of an adversary attack run")
    parser.add_argument("--natural", action="append", default=[], help="LABEL=DIR of a riskmap evaluate run")
    parser.add_argument("--ade", action="append", default=[], help="LABEL=FILE of an open-loop ADE record")
    parser.add_argument("--paired", action="append", default=[], help="A:B, two --attack labels")
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
    natural = _pairs(args.natural, "--natural")
    ade = _pairs(args.ade, "--ade")
    if attacks:
        lines += ["### Fresh CRASH (MAM+ASM) on held-out scenes", "",
                  ("| planner | collisions / scenes (95% CI) | natural: collisions / episodes | progress (m) "
                   "| open-loop ADE (m) |"), "|---|---|---|---|---|"]
    for label, root in attacks.items():
        s = json.loads((root / "summary.json").read_text())
        results["attacks"][label] = {k: s[k] for k in ("planner", "scenes", "count")} | {"summary": s["summary"]}
        lo, hi = s["summary"]["collision_ci95"]
        row = (f"| {label} (`{s['planner']}`) | {s['summary']['collisions']}/{s['summary']['scenes']} "
               f"({100 * s['summary']['collision_rate']:.0f}% [{100 * lo:.0f}–{100 * hi:.0f}]) |")
        if label in natural:
            planners = json.loads((natural[label] / "results.json").read_text())["planners"]
            table = planners.get(s["planner"]) or next(iter(planners.values()))   # the attacked planner's row
            collisions = round(table["collided_rate"] * table["episodes"])
            results["attacks"][label]["natural"] = {"episodes": table["episodes"], "collisions": collisions,
                                                    "distance_m": table["distance_m"]["mean"]}
            row += f" {collisions}/{table['episodes']} | {table['distance_m']['mean']:.1f} |"
        else:
            row += " – | – |"
        if label in ade:
            value = json.loads(ade[label].read_text())["ade_m"]["mean"]
            results["attacks"][label]["open_loop_ade_m"] = value
            row += f" {value:.2f} |"
        else:
            row += " – |"
        lines.append(row)
    if attacks:
        lines.append("")
    pairs = [pair.split(":") for pair in args.paired]
    if pairs:
        lines += ["| paired: A → B | common scenes | won against A only | won against B only | sign test p |",
                  "|---|---|---|---|---|"]
    results["paired"] = []
    for pair in pairs:
        if len(pair) != 2 or any(label not in attacks for label in pair):
            raise SystemExit(f"--paired {':'.join(pair)!r}: write A:B with two --attack labels")
        row = paired(attacks[pair[0]], attacks[pair[1]])
        results["paired"].append({"a": pair[0], "b": pair[1], **row})
        lines.append(f"| {pair[0]} → {pair[1]} | {row['scenes']} | {row['a_only']} | {row['b_only']} | {row['p']:.3f} |")
    if pairs:
        lines.append("")
    for label, root in _pairs(args.search, "--search").items():
        results["search"] += search_rows(label, root)
    if results["search"]:
        lines += ["### NSGA-II search at equal budget", "",
                  "| planner | template | pop x gen | collisions / evaluations (share, 95% CI) "
                  "| valid avoidable at-fault failures (share, 95% CI) |", "|---|---|---|---|---|"]
        lines += [f"| {r['planner']} (`{r['spec']}`) | {r['template']} | {r['budget']} | "
                  f"{_share(r['collisions'], r['evaluations'], r['ci95'])} | "
                  f"{_share(r['counted'], r['evaluations'], r['counted_ci95'])} |"
                  for r in results["search"]]
    write_json(out / "results.json", results)
    atomic_write(out / "tables.md", lambda f: f.write(("\n".join(lines) + "\n").encode()))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
