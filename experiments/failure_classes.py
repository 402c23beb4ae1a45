"""The failures that count among CRASH's wins: one row per attack run, and the floor scenes.

Reads `adversary attack` runs (OUT/attacks/*.json, each collision classified by
`riskmap.sim.failures` in the judge) and writes PREFIX.md and PREFIX.json: per run the wins
(collisions with the adversary) over the scenes, how many are valid attacks, avoidable, at fault
/ struck from behind / side, and how many count (valid, avoidable and at fault), with the valid
and counted shares of the wins; then, for the scenes named by `--floor` (those every planner
lost, experiments/README "The scenes every planner lost"), each run's class of each scene.

    .venv/bin/python experiments/failure_classes.py --runs runs/failures/highway_* \
        --floor 5,10,13,21,24,32,33,34,37 --out experiments/results/failures/highway
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from riskmap.infra.atomic import atomic_write, write_json
from riskmap.sim.failures import summarise_failures


def load_run(run: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((run / "attacks").glob("scene_*.json"))]


def run_row(name: str, records: list[dict]) -> dict:
    wins = [r for r in records if r.get("status") == "ok" and r["collision"]]
    classes = summarise_failures([r["metrics"].get("failure") for r in wins], len(records))
    return {"run": name, "scenes": len(records), "wins": len(wins), **classes,
            "valid_share_of_wins": classes["valid"] / len(wins) if wins and classes["valid"] is not None else None,
            "counted_share_of_wins": classes["counted"] / len(wins) if wins else None}


def scene_class(record: dict | None) -> str:
    """A scene's outcome in a few letters: "-" no win; else fault (F at fault, B struck from
    behind, S side), a for avoidable / u unavoidable, v valid / i invalid, * when it counts."""
    if record is None:
        return "?"
    if record.get("status") != "ok" or not record["collision"]:
        return "-"
    f = record["metrics"].get("failure")
    if not f:
        return "unknown"
    text = {"at fault": "F", "struck from behind": "B", "side": "S"}[f["fault"]]
    text += "a" if f["avoidable"] else "u"
    text += "v" if f.get("valid_attack") else "i"
    return text + ("*" if f["counts"] else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", nargs="+", type=Path, required=True)
    parser.add_argument("--floor", default="", help="comma-separated scene numbers")
    parser.add_argument("--out", type=Path, required=True, help="PREFIX of PREFIX.md and PREFIX.json")
    args = parser.parse_args()
    runs = {run.name: load_run(run) for run in args.runs if (run / "attacks").is_dir()}
    rows = [run_row(name, records) for name, records in runs.items()]
    lines = ["| run | wins / scenes | valid | avoidable | at fault / struck from behind / side | count | "
             "valid share of wins | counted share of wins |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        def pct(v):
            return "–" if v is None else f"{100 * v:.0f}%"
        lines.append(f"| {r['run']} | {r['wins']} / {r['scenes']} | {r['valid']} | {r['avoidable']} | "
                     f"{r['at_fault']} / {r['struck_from_behind']} / {r['side']} | {r['counted']} | "
                     f"{pct(r['valid_share_of_wins'])} | {pct(r['counted_share_of_wins'])} |")
    floor = [int(s) for s in args.floor.split(",") if s]
    floor_rows = {}
    if floor:
        lines += ["", "Floor scenes: F at fault, B struck from behind, S side; a avoidable, u unavoidable; "
                  "v valid, i invalid attack; * counts; - not lost.", "",
                  "| scene | " + " | ".join(runs) + " |", "|---|" + "---|" * len(runs)]
        for scene in floor:
            name = f"scene_{scene:05d}"
            cells = [scene_class(next((r for r in records if r.get("name") == name), None))
                     for records in runs.values()]
            floor_rows[name] = dict(zip(runs, cells))
            lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json(args.out.with_suffix(".json"), {"runs": rows, "floor": floor_rows})
    atomic_write(args.out.with_suffix(".md"), lambda f: f.write(("\n".join(lines) + "\n").encode()))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
