"""The failures that count among CRASH's wins: one row per attack run, and the floor scenes.

Reads `adversary attack` runs (OUT/attacks/*.json, each collision classified by
`riskmap.sim.records.failures` in the judge) and writes PREFIX.md and PREFIX.json: per run the wins
(collisions with the adversary) over the scenes, how many are valid attacks, avoidable, at fault
/ struck from behind / side, and how many count (valid, avoidable and at fault), with the valid
and counted shares of the wins; then, for the scenes named by `--floor` (those every planner
lost, experiments/README "The scenes every planner lost"), each run's class of each scene.

    .venv/bin/python experiments/failure_classes.py --runs runs/failures/highway_* \
        --floor 5,10,13,21,24,32,33,34,37 --out experiments/results/failures/highway
    .venv/bin/python experiments/failure_classes.py --simulator-limits 6 \
        --out experiments/results/failures/highway_env_limits

Records judged before the highway-env limits existed (every highway scene's attack judged under
a car's lateral limit) are judged again from the extremes they keep (`revalidated`), so every
row holds today's definition. `--simulator-limits N`: the kinematic extremes of every vehicle of
N highway-v0 episodes driven by highway-env's own IDM/MOBIL (the source of HIGHWAY_ENV_LIMITS).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from riskmap.infra.atomic import atomic_write, write_json
from riskmap.sim.records.failures import HIGHWAY_ENV_LIMITS, revalidated, summarise_failures


def load_run(run: Path) -> list[dict]:
    """A run's attack records, highway-env scenes' classifications under HIGHWAY_ENV_LIMITS."""
    records = [json.loads(p.read_text()) for p in sorted((run / "attacks").glob("scene_*.json"))]
    for r in records:
        if r.get("metrics") and not r["scene"].get("recording"):
            r["metrics"]["failure"] = revalidated(r["metrics"].get("failure"), HIGHWAY_ENV_LIMITS)
    return records


def simulator_limits(episodes: int) -> dict:
    """The extremes of `adversary_kinematics` over every vehicle (longer than 2 s) of `episodes`
    highway-v0 episodes (seed 3000, 30 s each) that highway-env's IDM/MOBIL drives: p50, p90,
    p99 and max of each."""
    import numpy as np

    from riskmap.registry import make_planner
    from riskmap.sim.loop.rollout import DriveHooks
    from riskmap.sim.records.failures import adversary_kinematics
    from riskmap.sim.worlds.episode import make_env
    from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

    env = make_env("highway-v0", 10)
    values: dict[str, list[float]] = {}
    for episode in range(episodes):
        driven = {}
        drive_episode(env, make_planner("idm", seed=0), DriveConfig("highway-v0", episodes, seed=3000, episode_s=30.0),
                      episode, hooks=DriveHooks(on_step=lambda run: driven.update(run=run)))
        tracks = driven["run"].recorder.tracks()
        states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
        for agent in range(states.shape[0]):
            track = states[agent][valid[agent]]
            if len(track) < 20 or sizes[agent, 0] < 3.0:       # vehicles seen for 2 s or more
                continue
            for key, value in adversary_kinematics(track, 0.1, 4.0).items():
                values.setdefault(key, []).append(value)
    return {key: {"vehicles": len(v), **{name: float(q) for name, q in
                                         zip(("p50", "p90", "p99", "max"), np.percentile(v, [50, 90, 99, 100]))}}
            for key, v in values.items()}


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
    parser.add_argument("--runs", nargs="+", type=Path, default=[])
    parser.add_argument("--simulator-limits", type=int, default=0, metavar="N",
                        help="measure highway-env's own drivers over N episodes instead")
    parser.add_argument("--floor", default="", help="comma-separated scene numbers")
    parser.add_argument("--out", type=Path, required=True, help="PREFIX of PREFIX.md and PREFIX.json")
    args = parser.parse_args()
    if args.simulator_limits:
        measured = simulator_limits(args.simulator_limits)
        write_json(args.out.with_suffix(".json"), measured)
        print(json.dumps(measured, indent=1))
        return
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
