"""PNG panels of finished CRASH attacks: re-drive the planner against the stored trajectories.

    python experiments/crash_panels.py --run out/crash/highway/idm_crash --scenes data/attack/highway \
        --success 3 --failed 1 --out experiments/results/crash/panels

Picks the first `--success` scenes whose attack collided and the first `--failed` that did not (in
scene order, so the choice is not a beauty contest), drives the run's planner against the stored
tracks once more (rollouts are deterministic) and writes one panel per scene.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from adversary.crash.features import scene_tensors
from adversary.crash.judge import judge, rollout
from adversary.crash.panel import save_attack_panel
from adversary.crash.scenes import load_record
from adversary.crash.train_traffic import load_traffic_model
from riskmap.registry import cached_planner


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", required=True, help="an `adversary attack` output directory")
    parser.add_argument("--scenes", required=True)
    parser.add_argument("--success", type=int, default=3)
    parser.add_argument("--failed", type=int, default=1)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    run = Path(args.run)
    meta = json.loads((run / "run.json").read_text())
    spec = meta["planner"]
    planner = cached_planner(spec, meta["seed"])
    _, features, _ = load_traffic_model(Path(meta["traffic_model"]))
    records = sorted((run / "attacks").glob("*.json"))
    chosen = {True: [], False: []}
    for path in records:
        r = json.loads(path.read_text())
        if r["status"] == "ok" and len(chosen[r["collision"]]) < (args.success if r["collision"] else args.failed):
            chosen[r["collision"]].append(r)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for collided, items in chosen.items():
        for r in items:
            record = load_record(Path(args.scenes) / f"{r['name']}.npz")
            rows = scene_tensors(record.window, features).rows[1:]
            tracks = np.asarray(r["tracks"])
            result = rollout(record, tracks, rows, planner, spec)
            metrics = judge(record, tracks, rows, r["adversary_row"], planner, spec, result=result)
            if metrics["collision"] != r["collision"]:
                print(f"warning: {r['name']}: the re-drive does not reproduce the stored verdict")
            kind = "success" if collided else "failed"
            path = out / f"{run.parent.name}_{run.name}_{r['name']}_{kind}.png"
            save_attack_panel(record, tracks, rows, r["adversary_row"], result, metrics, path,
                              f"{record.scene.where} | {spec} | {r['selector']}")
            print(path)


if __name__ == "__main__":
    main()
