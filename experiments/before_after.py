"""Are a refactor's results unchanged? The US-101 held-out Table I rows and a CRASH run on 10
scenes of each family, run at a reference commit and at this tree, and every number compared.

The reference commit is checked out into a git worktree under OUT/ref_tree and run with the same
venv, its library first on PYTHONPATH; this tree runs with its own. Each row's results.json (or
the attack's summary.json) is flattened to its numeric leaves and the two compared: the script
prints one line per row, "equal" or each common leaf that differs (fields only one side
has are listed apart), and writes OUT/comparison.json.
Timings (seconds, plan milliseconds) and paths differ by nature and are left out of the
comparison. Rows finished earlier are kept (each command runs with --resume).

    .venv/bin/python experiments/before_after.py --ref 6275d37 --out runs/before_after \
        --us101 $US101 [--episodes 12] [--scenes 10]

US101 is the folder of CommonRoad NGSIM scenario files `USA_US101-*_T-1.xml`; configurations
15-18 are the held-out ones, as in experiments/README.md "Table I".
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
# leaves whose value depends on the machine or the folder, not on the results
VOLATILE = ("seconds", "_ms", "ms_", "time_s", "timings", "wall", "path", "out", "git_commit", "created",
            "package_version", "run_dir", "started", "finished")


def rows(us101: Path, episodes: int, scenes: int) -> dict[str, list[str]]:
    """name -> command (argv after the console script's name); OUT is filled in per tree."""
    held_out = sorted(str(p) for k in (15, 16, 17, 18) for p in us101.glob(f"USA_US101-{k}_*_T-1.xml"))
    planners = "replay,cv,idm,riskmap:checkpoints/riskmap_us101,riskmap:checkpoints/riskmap_st_us101"
    common = ["evaluate", "--commonroad", *held_out, "--planners", planners, "--max-episodes", str(episodes)]
    return {
        "table1_human_log": ["riskmap", *common, "--goal", "human", "--goal-variance", "0.25", "--mode", "log"],
        "table1_route_reactive": ["riskmap", *common, "--goal", "route", "--mode", "reactive"],
        "crash_highway": ["adversary", "attack", "--planner", "riskmap:checkpoints/riskmap_st_highway",
                          "--scenes", str(ROOT / "data" / "attack" / "highway"), "--count", str(scenes)],
        "crash_us101": ["adversary", "attack", "--planner", "riskmap:checkpoints/riskmap_st_us101",
                        "--scenes", str(ROOT / "data" / "attack" / "us101"), "--count", str(scenes)],
    }


def run_row(tree: Path, argv: list[str], out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    cmd = [str(BIN / argv[0]), *argv[1:], "--out", str(out), "--resume", "--quiet"]
    subprocess.run(cmd, cwd=tree, env=env, check=True)
    for name in ("results.json", "summary.json"):
        if (out / name).exists():
            return json.loads((out / name).read_text())
    raise SystemExit(f"{out}: neither results.json nor summary.json was written")


def leaves(value, prefix: str = "") -> dict[str, float]:
    """Numeric leaves of a JSON value by dotted key, volatile keys left out."""
    if isinstance(value, dict):
        return {k: v for key, item in value.items() if not any(word in key for word in VOLATILE)
                for k, v in leaves(item, f"{prefix}{key}.").items()}
    if isinstance(value, list):
        return {k: v for i, item in enumerate(value) for k, v in leaves(item, f"{prefix}{i}.").items()}
    if isinstance(value, bool) or isinstance(value, (int, float)):
        return {prefix.rstrip("."): float(value)}
    return {}


def differences(before: dict, after: dict) -> tuple[list[str], list[str]]:
    """(values that changed among the leaves both have, leaves only one side has): a refactor
    may add fields to a results file; it must not change one."""
    a, b = leaves(before), leaves(after)
    changed = [f"{key}: {a[key]} -> {b[key]}" for key in sorted(set(a) & set(b)) if a[key] != b[key]]
    one_side = [f"only before: {key}" for key in sorted(set(a) - set(b))] + \
               [f"only after: {key}" for key in sorted(set(b) - set(a))]
    return changed, one_side


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ref", required=True, help="the commit to compare against")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--us101", type=Path, required=True, help="folder of USA_US101-*_T-1.xml files")
    parser.add_argument("--episodes", type=int, default=12, help="recorded vehicles per Table I row (default 12)")
    parser.add_argument("--scenes", type=int, default=10, help="CRASH scenes per family (default 10)")
    parser.add_argument("--only", nargs="+", help="run only these rows")
    args = parser.parse_args(argv)
    if not args.us101.is_dir() or not any(args.us101.glob("USA_US101-1[5-8]_*_T-1.xml")):
        print(f"--us101 {args.us101}: no USA_US101-15..18 files there; give the folder of the US-101 "
              "CommonRoad scenario files", file=sys.stderr)
        return 2
    ref_tree = args.out / "ref_tree"
    if not ref_tree.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(ref_tree), args.ref], cwd=ROOT, check=True,
                       stdout=subprocess.DEVNULL)
    comparison = {}
    for name, argv_row in rows(args.us101, args.episodes, args.scenes).items():
        if args.only and name not in args.only:
            continue
        before = run_row(ref_tree.resolve(), argv_row, (args.out / "before" / name).resolve())
        after = run_row(ROOT, argv_row, (args.out / "after" / name).resolve())
        changed, one_side = differences(before, after)
        comparison[name] = {"equal": not changed, "differences": changed, "fields_on_one_side": one_side}
        print(f"{name}: " + ("equal" if not changed else f"{len(changed)} values differ")
              + (f" ({len(one_side)} fields on one side only)" if one_side else ""), flush=True)
        for line in (changed + one_side)[:20]:
            print("   ", line)
    (args.out / "comparison.json").write_text(json.dumps(comparison, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
