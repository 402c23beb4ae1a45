"""The guard against attacks made against itself: CRASH optimised against each guard variant.

For a scenario family and an inner planner, CRASH (MAM+ASM, the attack's default settings, as in
`crash_tables.py`'s "lr0.15" rows) attacks the same held-out scenes three times: the planner
alone (`SPEC`), with the deceleration plan always on at high speed (`guard-always:SPEC`) and with
the TGAT-triggered guard (`guard:SPEC`). Unlike `guard_adversarial.py` (the attack on the planner
alone replayed against the guarded variants), the adversary here meets the guard while it
optimises: its replanned closed-loop drives run the guarded planner.

Every attack record is then driven once more by the planner it attacked
(`adversary.crash.redrive`) to read the guard's decision frames and interventions and the
ego's progress; the table compares the variants on the scenes all three finished, with 95%
Wilson intervals on the collision rates.

    python experiments/guard_adaptive.py --family highway --inner idm --count 40
    python experiments/guard_adaptive.py --family intersection --inner riskmap --count 20
    python experiments/guard_adaptive.py --table experiments/results/guard/adaptive

Attacks: out/crash/<family>/<inner>_crash_lr0.15 (alone: the `crash_tables.py` run),
out/guard_adaptive/<family>/<inner>_<variant>/ (guarded); drives:
out/guard_adaptive/<family>/<inner>_<variant>/drives/<scene>.json (atomic, resumable).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from adversary.crash.attack import REPLAN_EVERY, AttackConfig
from adversary.crash.guard_data import read_attack_run
from adversary.crash.redrive import redrive_attack
from adversary.crash.run import run_attacks
from adversary.crash.scenes import load_record
from riskmap.evaluation.guard_tables import intervention_totals, markdown_table, print_table, ratio_cell
from riskmap.infra.atomic import write_json
from riskmap.infra.stats import wilson
from riskmap.planner.shipped import shipped_spec
from riskmap.registry import cached_planner

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "guard_adaptive"
VARIANTS = {"alone": "", "always": "guard-always:", "tgat": "guard:"}
ATTACK = {"lr": 0.15}     # crash_tables.py's "lr0.15" rows: the attack's defaults


def attack_dir(family: str, inner: str, variant: str) -> Path:
    if variant == "alone":        # crash_tables.py's run of planner `inner`, selector crash, variant lr0.15
        return ROOT / "out" / "crash" / family / f"{inner}_crash_lr0.15"
    return OUT / family / f"{inner}_{variant}"


def attack(family: str, inner: str, variant: str, count: int) -> None:
    spec = VARIANTS[variant] + shipped_spec(inner, family)
    config = AttackConfig(selector="crash", replan_every=REPLAN_EVERY[inner], **ATTACK)
    run_attacks(spec, ROOT / "data" / "attack" / family, count, config, seed=0,
                out=attack_dir(family, inner, variant), traffic=ROOT / "checkpoints" / f"crash_traffic_{family}",
                selectors=ROOT / "checkpoints" / f"crash_selector_{family}", resume=True, progress=True)


def drive(family: str, inner: str, variant: str, count: int) -> None:
    run = read_attack_run(attack_dir(family, inner, variant))
    drives = OUT / family / f"{inner}_{variant}" / "drives"
    for name in run.names[:count]:
        path = drives / f"{name}.json"
        attack_record = json.loads((run.path / "attacks" / f"{name}.json").read_text())
        if path.exists() or attack_record.get("status") != "ok":
            continue
        spec = attack_record["planner"]        # the attacked planner, guarded or not
        result = redrive_attack(load_record(run.scenes / f"{name}.npz"), attack_record,
                                cached_planner(spec, run.seed), spec)
        result.update({"scene": name, "attack_collision": bool(attack_record["collision"])})
        write_json(path, result)


def summarise(count: int | None = None) -> list[dict]:
    rows = []
    for family_dir in sorted(p for p in OUT.glob("*") if p.is_dir()):
        inners = sorted({p.name.rsplit("_", 1)[0] for p in family_dir.glob("*_*") if (p / "drives").is_dir()})
        for inner in inners:
            cells = {v: family_dir / f"{inner}_{v}" / "drives" for v in VARIANTS}
            if not all(c.is_dir() for c in cells.values()):
                continue
            common = set.intersection(*({p.stem for p in c.glob("scene_*.json")} for c in cells.values()))
            names = sorted(common)[:count]
            for variant, cell in cells.items():
                records = [json.loads((cell / f"{n}.json").read_text()) for n in names]
                if not records:
                    continue
                rows.append({"family": family_dir.name, "inner": inner, "variant": variant,
                             "scenes": len(records),
                             "collision": wilson(sum(r["collision"] for r in records), len(records)),
                             "collision_any": sum(r["collision_any"] for r in records),
                             "progress_m": float(np.mean([r["progress_m"] for r in records])),
                             **intervention_totals(records),
                             "hard": sum(r["guard"].get("hard", 0) for r in records if "guard" in r)})
    return rows


COLUMNS = ("family", "planner", "variant", "scenes", "collisions with adversary [95% CI]", "any collision",
           "progress (m, 6 s)", "interventions / frames", "BDI ratio")


def markdown(rows: list[dict]) -> str:
    def cells(r: dict) -> tuple:
        c = r["collision"]
        return (r["family"], r["inner"], r["variant"], r["scenes"],
                f"{c['k']} ({100 * c['value']:.0f}% [{100 * c['lo']:.0f}–{100 * c['hi']:.0f}])",
                r["collision_any"], f"{r['progress_m']:.1f}", f"{r['interventions']} / {r['frames'] or '–'}",
                ratio_cell(r))
    return markdown_table(COLUMNS, map(cells, rows))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--family", choices=("highway", "intersection"))
    parser.add_argument("--inner", choices=("idm", "riskmap"))
    parser.add_argument("--variants", default="alone,always,tgat")
    parser.add_argument("--count", type=int, default=40, help="the first COUNT held-out attack scenes")
    parser.add_argument("--table", type=Path, default=None, help="write PREFIX.json and PREFIX.md only")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    if args.table is None:
        if not (args.family and args.inner):
            parser.error("--family and --inner are needed unless --table is given")
        for variant in args.variants.split(","):
            attack(args.family, args.inner, variant, args.count)
            drive(args.family, args.inner, variant, args.count)
    print_table(summarise(), markdown, args.table)


if __name__ == "__main__":
    main()
