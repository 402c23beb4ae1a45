"""How many attack candidates Motion-Aware Masking removes in the held-out scenes.

    python experiments/crash_mam_check.py --count 100   # -> experiments/results/crash/mam_check.json

A candidate is a non-ego agent of the window; MAM removes those whose mean past step is at most
1e-4 m. When it removes none, DS+MAM equals DS and MAM only changes which ASM checkpoint is used.
The simulated families' scenes carry parked and stopped vehicles (`adversary scenes
--static-agents 3`); recorded US-101 has whatever stood still in the recording.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from adversary.crash.batch import collate
from adversary.crash.features import scene_tensors
from adversary.crash.scenes import load_record
from adversary.crash.selection import candidates
from riskmap.infra.atomic import write_json

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=100)
    args = parser.parse_args()
    out = {}
    for family in ("highway", "intersection", "us101"):
        scenes = ROOT / "data" / "attack" / family
        if not (scenes / "index.json").exists():
            continue
        names = json.loads((scenes / "index.json").read_text())["scenes"][: args.count]
        masked = total = affected = 0
        for name in names:
            batch = collate([scene_tensors(load_record(scenes / f"{name}.npz").window)])
            every, moving = candidates(batch, mam=False)[0], candidates(batch, mam=True)[0]
            masked += int((every & ~moving).sum())
            total += int(every.sum())
            affected += int((every & ~moving).any())
        out[family] = {"scenes": len(names), "candidates": total, "masked": masked, "scenes_affected": affected}
        print(family, out[family])
    write_json(ROOT / "experiments" / "results" / "crash" / "mam_check.json", out)


if __name__ == "__main__":
    main()
