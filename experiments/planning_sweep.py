"""Closed-loop sweep of a checkpoint's planning-time settings (its sidecar's `planning` section).

Each `--variant NAME=JSON` becomes a copy of the checkpoint (the same weights) whose sidecar's
planning section is updated with JSON, written to VARIANTS/NAME; each is driven by `riskmap drive`
on the same episodes (OUT/NAME, resumable), beside any `--baseline NAME=SPEC` planners, and the
table (episodes, collisions, off-road, mean distance, yielding events per episode) goes to --table.

    .venv/bin/python experiments/planning_sweep.py --checkpoint checkpoints/riskmap_st_intersection \
        --env intersection-v0 --episodes 60 --seed 300 --variants runs/stvar --out runs/val60 \
        --baseline teacher=yielding --baseline idm=idm \
        --variant-file experiments/results/spacetime/intersection_planning_variants.json \
        --table experiments/results/spacetime/intersection_planning_sweep_val.json
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

from riskmap.infra.atomic import write_json
from riskmap.infra.checkpoint import resolve_checkpoint


def named(text: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"{text!r}: expected NAME=VALUE")
    return name, value


def write_variant(checkpoint: Path, planning: dict, out: Path) -> Path:
    """A copy of `checkpoint` (weights unchanged) with its sidecar's planning section updated."""
    side = json.loads(checkpoint.with_suffix(".json").read_text())
    side["planning"] = {**side.get("planning", {}), **planning}
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(checkpoint.with_suffix(".safetensors"), out.parent / f"{out.name}.safetensors")
    write_json(out.parent / f"{out.name}.json", side)
    return out


def row(run: Path) -> dict:
    episodes = [json.loads(p.read_text()) for p in sorted((run / "episodes").glob("episode_*.json"))]
    n = len(episodes)
    return {"episodes": n,
            "collisions": sum(bool(e["collided"]) for e in episodes),
            "off_road": sum(bool(e.get("off_road")) for e in episodes),
            "distance_m": sum(e["distance_m"] for e in episodes) / max(n, 1),
            "yield_events_per_episode": sum(e["yield_events"] for e in episodes) / max(n, 1)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", required=True, help="the checkpoint whose planning section is varied")
    p.add_argument("--env", required=True, help="highway-env id, e.g. intersection-v0")
    p.add_argument("--episodes", type=int, required=True, help="episodes per planner")
    p.add_argument("--seed", type=int, default=0, help="riskmap drive's --seed (default 0)")
    p.add_argument("--variants", type=Path, required=True, help="folder for the variant checkpoints")
    p.add_argument("--out", type=Path, required=True, help="folder of the drive runs (OUT/NAME)")
    p.add_argument("--variant", type=named, action="append", default=[], help="NAME=JSON planning update")
    p.add_argument("--variant-file", type=Path, help="a JSON object NAME -> planning update, as --variant")
    p.add_argument("--baseline", type=named, action="append", default=[], help="NAME=planner SPEC")
    p.add_argument("--table", type=Path, required=True, help="the table's JSON file")
    args = p.parse_args(argv)
    riskmap = str(Path(sys.executable).with_name("riskmap"))
    source = resolve_checkpoint(args.checkpoint)
    runs = {}
    for name, spec in args.baseline:
        runs[name] = ("planner", spec)
    variants = {name: json.loads(planning) for name, planning in args.variant}
    if args.variant_file:
        variants = {**json.loads(args.variant_file.read_text()), **variants}
    for name, planning in variants.items():
        runs[name] = ("checkpoint", str(write_variant(source, planning, args.variants / name)))
    table = {}
    for name, (flag, value) in runs.items():
        out = args.out / name
        cmd = [riskmap, "drive", f"--{flag}", value, "--env", args.env, "--episodes", str(args.episodes),
               "--seed", str(args.seed), "--out", str(out), "--quiet"]
        if (out / "episodes").exists():
            cmd.append("--resume")
        subprocess.run(cmd, check=True)
        table[name] = {"planning": variants.get(name), "spec": value, **row(out)}
        print(name, table[name], flush=True)
    write_json(args.table, {"env": args.env, "episodes": args.episodes, "seed": args.seed,
                                   "checkpoint": str(args.checkpoint), "rows": table})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
