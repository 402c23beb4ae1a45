"""`make bench`: planning, training, closed-loop and attack speed of this tree against a reference commit.

The reference commit (`--reference`, default the parent of HEAD) is checked out into a temporary
git worktree. Every benchmark then runs once in each tree per round, the reference first,
alternating over `--rounds`, with the same interpreter; a tree's run has that tree first on
PYTHONPATH (and its own command-line entry points), so the ratio compares code, not machine
moments. The inputs are made once, by this tree, and shared: a highway dataset for training,
CRASH scenes, and the shipped checkpoints of this tree.

    planning      experiments/bench_planner.py, per resolution: median ms per stage and total
    training      `riskmap train`, 2 epochs: training windows per second of each epoch
    closed loop   `riskmap drive`, IDM and the risk-aware planner: wall s per simulated s
    crash         `adversary attack` (MAM+ASM) against the risk-aware planner: s per scene
    campaign      `adversary stress-test` of experiments/campaigns/demo.yaml: wall s

Writes experiments/results/bench.json and bench.md (medians over rounds; ratio = reference ÷
current, above 1 = faster now).

    .venv/bin/python experiments/bench_all.py [--reference COMMIT] [--rounds 1] [--skip campaign]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCHES = ("planning", "training", "closed_loop", "crash", "campaign")


def run(tree: Path, target: str, args: list[str], cwd: Path | None = None) -> float:
    """Wall seconds of `target` (a script path, or "riskmap" / "adversary" for the command line)
    run with `args` on `tree`'s code: the tree goes first on sys.path and the editable install's
    import hook (which would map the packages to this checkout) is dropped."""
    if target in ("riskmap", "adversary"):
        call = f"from {target}.cli import main; sys.argv = [{target!r}] + ARGS; sys.exit(main())"
    else:
        call = (f"import runpy; sys.argv = [{target!r}] + ARGS; "
                f"runpy.run_path({target!r}, run_name='__main__')")
    code = ("import json, sys; sys.meta_path[:] = [f for f in sys.meta_path "
            "if '__editable__' not in getattr(f, '__module__', '')]; "
            f"sys.path.insert(0, {str(tree)!r}); ARGS = json.loads(sys.stdin.read()); " + call)
    env = dict(os.environ, OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "2"))
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-c", code], input=json.dumps(args), cwd=cwd or tree,
                            env=env, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        sys.exit(f"bench: {target} {' '.join(args)} failed on {tree}:\n{result.stderr[-2000:]}")
    return time.perf_counter() - start


def bench_planning(tree: Path, work: Path, calls: int) -> dict:
    out = work / "planner.json"
    run(tree, str(ROOT / "experiments/bench_planner.py"), ["--calls", str(calls), "--out", str(out)])
    rows = json.loads(out.read_text())["rows"]
    return {f"{stage} {row['resolution']}x{row['resolution']} (ms)": row[f"{stage}_ms"]
            for row in rows for stage in ("raster", "network", "vi", "svf", "sampler", "total")}


def bench_training(tree: Path, work: Path, data: Path, windows: int) -> dict:
    out = work / "train"
    shutil.rmtree(out, ignore_errors=True)
    run(tree, "riskmap", ["train", "--data", str(data), "--out", str(out), "--epochs", "2",
                                "--max-windows", str(windows), "--quiet"])
    with (out / "log.csv").open() as f:
        epochs = list(csv.DictReader(f))
    return {f"training epoch {int(e['epoch']) + 1} (windows/s)": windows / float(e["seconds"])
            for e in epochs}


def bench_closed_loop(tree: Path, work: Path, episodes: int) -> dict:
    row = {}
    for env_id, checkpoint in (("highway-v0", "riskmap_highway"),
                               ("intersection-v0", "riskmap_intersection")):
        for planner in (["--planner", "idm"], ["--checkpoint", str(ROOT / "checkpoints" / checkpoint)]):
            out = work / "drive"
            shutil.rmtree(out, ignore_errors=True)
            wall = run(tree, "riskmap", ["drive", *planner, "--env", env_id, "--episodes",
                                               str(episodes), "--seed", "0", "--out", str(out), "--quiet"])
            simulated = sum(json.loads(p.read_text())["simulated_s"]
                            for p in (out / "episodes").glob("*.json"))
            name = "idm" if planner[1] == "idm" else "risk-aware"
            row[f"drive {env_id} {name} (wall s / sim s)"] = wall / simulated
    return row


def bench_crash(tree: Path, work: Path, scenes: Path, count: int) -> dict:
    out = work / "attack"
    shutil.rmtree(out, ignore_errors=True)
    wall = run(tree, "adversary", [
        "attack", "--planner", f"riskmap:{ROOT / 'checkpoints/riskmap_highway'}", "--scenes",
        str(scenes), "--count", str(count), "--out", str(out), "--workers", "1", "--quiet"])
    return {"CRASH attack highway (s / scene)": wall / count}


def bench_campaign(tree: Path, work: Path) -> dict:
    out = work / "stress"
    shutil.rmtree(out, ignore_errors=True)
    wall = run(tree, "adversary", ["stress-test", "--config", "experiments/campaigns/demo.yaml",
                                         "--out", str(out), "--workers", "2"])
    return {"demo campaign (wall s)": wall}


def table(reference: dict, current: dict, commit: str) -> str:
    lines = [f"| benchmark | reference {commit} | current | ratio |", "|---|---:|---:|---:|"]
    for key, now in current.items():
        ref = reference.get(key)
        if ref is None:
            lines.append(f"| {key} | – | {now:.3g} | – |")
            continue
        # Higher is better for windows/s; lower for times: the ratio always reads "× faster now".
        ratio = now / ref if "windows/s" in key else ref / now
        lines.append(f"| {key} | {ref:.3g} | {now:.3g} | {ratio:.2f}× |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", default="HEAD~1", help="commit to compare with (default HEAD~1)")
    parser.add_argument("--rounds", type=int, default=1, help="runs of every benchmark per tree")
    parser.add_argument("--skip", action="append", default=[], choices=BENCHES)
    parser.add_argument("--calls", type=int, default=20, help="plans per resolution")
    parser.add_argument("--train-windows", type=int, default=256)
    parser.add_argument("--episodes", type=int, default=2, help="closed-loop episodes per case")
    parser.add_argument("--scenes", type=int, default=4, help="CRASH scenes")
    parser.add_argument("--out", type=Path, default=ROOT / "experiments/results/bench.json")
    args = parser.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", args.reference], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        reference_tree = tmp / "reference"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet", str(reference_tree), commit],
                       cwd=ROOT, check=True)
        try:
            inputs = tmp / "inputs"
            data, scenes = inputs / "highway", inputs / "scenes"
            if "training" not in args.skip:
                run(ROOT, "riskmap", ["collect", "--env", "highway-v0", "--episodes", "12",
                                            "--seed", "0", "--out", str(data), "--workers", "2"])
            if "crash" not in args.skip:
                run(ROOT, "adversary", ["scenes", "--env", "highway-v0", "--seed", "300",
                                              "--count", str(args.scenes), "--out", str(scenes),
                                              "--quiet"])
            results = {"reference": [], "current": []}
            for _ in range(args.rounds):
                for side, tree in (("reference", reference_tree), ("current", ROOT)):
                    work = tmp / side
                    work.mkdir(exist_ok=True)
                    row = {}
                    if "planning" not in args.skip:
                        row |= bench_planning(tree, work, args.calls)
                    if "training" not in args.skip:
                        row |= bench_training(tree, work, data, args.train_windows)
                    if "closed_loop" not in args.skip:
                        row |= bench_closed_loop(tree, work, args.episodes)
                    if "crash" not in args.skip:
                        row |= bench_crash(tree, work, scenes, args.scenes)
                    if "campaign" not in args.skip:
                        row |= bench_campaign(tree, work)
                    results[side].append(row)
                    print(f"{side}: " + ", ".join(f"{k} {v:.3g}" for k, v in row.items()), flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(reference_tree)], cwd=ROOT,
                           check=False)
    medians = {side: {k: statistics.median(r[k] for r in rows) for k in rows[0]}
               for side, rows in results.items()}
    text = table(medians["reference"], medians["current"], commit)
    print(text)
    machine = {"cpus": os.cpu_count(), "machine": platform.machine(), "python": platform.python_version()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"reference": commit, "rounds": args.rounds, "machine": machine,
                                    "runs": results, "medians": medians}, indent=2) + "\n")
    args.out.with_suffix(".md").write_text(text + "\n")


if __name__ == "__main__":
    main()
