"""What hardening could reach on the held-out highway scenes: every measured planner's fresh CRASH
wins against its progress in natural traffic, and the scenes that every attacked planner lost.

    python experiments/harden_ceiling.py --points experiments/results/harden/ceiling/frontier.csv \
        --attack original=runs/orig/attack --attack replan_10hz=runs/replan_10hz/attack ... \
        --out experiments/results/harden/ceiling

`--points` (optional): the measured planners, one row each (label, group, crash_wins, crash_scenes,
progress_m, section: the experiments/README section whose table holds the row); the first row
is the original, which progress is measured against.
`--attack LABEL=DIR`: `adversary attack --out` runs on the same held-out scenes (any planners);
a scene that every one of them lost to the attack is on the floor: no planner measured kept it.

Writes frontier.png (the issue's target region shaded, the floor drawn), floor.json and floor.md.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

from riskmap.infra.atomic import atomic_write, write_json

TARGET_PROGRESS_PCT = -5.0      # the "progress within 5%"
TARGET_SHARE = 0.5              # fresh success at most half the original's


def read_points(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit(f"--points {path}: no rows")
    for row in rows:
        row["crash_wins"], row["crash_scenes"] = int(row["crash_wins"]), int(row["crash_scenes"])
        row["progress_m"] = float(row["progress_m"])
    base = rows[0]["progress_m"]
    for row in rows:
        row["progress_pct"] = 100.0 * (row["progress_m"] / base - 1.0)
    return rows


def collided_scenes(attack_dir: Path) -> tuple[set[str], set[str]]:
    """(every scene attacked, the scenes the attack won) of an `adversary attack --out` run."""
    records = sorted((attack_dir / "attacks").glob("*.json"))
    if not records:
        raise SystemExit(f"--attack {attack_dir}: no attacks/*.json; give an `adversary attack --out` run")
    done, won = set(), set()
    for path in records:
        done.add(path.stem)
        if json.loads(path.read_text()).get("collision"):
            won.add(path.stem)
    return done, won


def floor(attacks: dict[str, Path]) -> dict:
    """Scenes common to every run, and how many of the runs lost each of them."""
    runs = {label: collided_scenes(path) for label, path in attacks.items()}
    common = set.intersection(*(done for done, _ in runs.values()))
    lost_by = {scene: sum(scene in won for _, won in runs.values()) for scene in sorted(common)}
    return {"runs": {label: {"won": len(won & common)}
                     for label, (_, won) in runs.items()},
            "scenes": len(common), "lost_by": lost_by,
            "lost_by_all": [s for s, n in lost_by.items() if n == len(runs)]}


def plot(points: list[dict], result: dict | None, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = points[0]["crash_scenes"]
    target = TARGET_SHARE * points[0]["crash_wins"]
    fig, ax = plt.subplots(figsize=(9, 5.5))
    ax.axvspan(TARGET_PROGRESS_PCT, 12, ymax=(target + 0.5) / (scenes + 1), color="tab:green", alpha=0.15,
               label=f"the target: ≤ {target:g}/{scenes} and progress within 5%")
    if result is not None:
        ax.axhline(len(result["lost_by_all"]), color="tab:red", ls="--", lw=1,
                   label=f"scenes all {len(result['runs'])} attacked planners lost: {len(result['lost_by_all'])}")
    for i, group in enumerate(dict.fromkeys(p["group"] for p in points)):
        pts = [p for p in points if p["group"] == group]
        ax.scatter([p["progress_pct"] for p in pts], [p["crash_wins"] for p in pts],
                   marker="*" if group == "original" else "os^Dvp<>h"[i % 9],
                   s=180 if group == "original" else 45, label=group, zorder=3)
    ax.set_xlim(-100, 12)
    ax.set_ylim(-0.5, scenes + 0.5)
    ax.set_xlabel("progress in natural traffic against the original (%)")
    ax.set_ylabel(f"fresh CRASH wins of {scenes} held-out scenes")
    ax.set_title("Highway planners measured for hardening: none reaches the target")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, lambda f: fig.savefig(f, format="png", dpi=110))
    plt.close(fig)


def markdown(points: list[dict], result: dict | None) -> str:
    lines = []
    if points:
        target = TARGET_SHARE * points[0]["crash_wins"]
        inside = [p["label"] for p in points
                  if p["crash_wins"] <= target and p["progress_pct"] >= TARGET_PROGRESS_PCT]
        lines += [(f"Planners measured: {len(points)}; inside the target (≤ {target:g} wins, progress ≥ "
                   f"{TARGET_PROGRESS_PCT:g}%): {', '.join(inside) if inside else 'none'}."), ""]
    if result is not None:
        lines += [(f"Floor over {len(result['runs'])} attack runs on {result['scenes']} common scenes: "
                   f"{len(result['lost_by_all'])} lost by every run ({', '.join(result['lost_by_all'])})."), "",
                  "| run | wins on the common scenes |", "|---|---|"]
        lines += [f"| {label} | {r['won']} |" for label, r in result["runs"].items()]
        counts = sorted(result["lost_by"].values(), reverse=True)
        lines += ["", "| lost by at least k runs | scenes |", "|---|---|"]
        lines += [f"| {k} | {sum(c >= k for c in counts)} |" for k in range(len(result["runs"]), 0, -1)]
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--points", type=Path, default=None, help="without it: the floor alone, no figure")
    p.add_argument("--attack", action="append", default=[], metavar="LABEL=DIR")
    p.add_argument("--out", type=Path, default=Path("experiments/results/harden/ceiling"))
    args = p.parse_args()
    attacks = {}
    for value in args.attack:
        label, _, path = value.partition("=")
        if not label or not path:
            raise SystemExit(f"--attack {value!r}: write LABEL=DIR")
        attacks[label] = Path(path)
    if args.points is None and not attacks:
        raise SystemExit("give --points, --attack LABEL=DIR, or both")
    points = read_points(args.points) if args.points is not None else []
    result = floor(attacks) if attacks else None
    if points:
        plot(points, result, args.out / "frontier.png")
    if result is not None:
        write_json(args.out / "floor.json", result)
    text = markdown(points, result)
    atomic_write(args.out / "floor.md", lambda f: f.write(text.encode()))
    print(text, end="")


if __name__ == "__main__":
    main()
