"""The guard's closed-loop table on adversarial scenes (the paper's Tables 2–3 analogue).

CRASH attacks (`adversary attack`) were generated against a planner; here the same generated
trajectories of the same scenes are driven again (`adversary.crash.redrive`) by the
planner alone, with the deceleration plan always on at high speed (`guard-always:SPEC`) and with
the TGAT-triggered plan (`guard:SPEC`). The adversary does not react to the guard: the
trajectories were optimised against the unguarded planner, so the guarded rows are a transfer
setting (the guard meets the attack that beat the planner, not an attack made against itself).

Per record: collision with the adversary and with anyone (box IoU > 0.02, `judge`), the ego's
progress over the attack horizon (path length t0 → t0 + 6 s; the rollout ignores contact, so
every variant drives the whole horizon), and the guard's decision frames and interventions (BDI
intervention ratio = interventions / decision frames, over the whole 8 s rollout).

    python experiments/guard_adversarial.py --attacks out/att/highway/idm_distance \
        --attacks out/att/intersection/idm_distance --count 60 --out out/guard_adv
    python experiments/guard_adversarial.py --out out/guard_adv --table experiments/results/guard/adversarial/table

Per record: OUT/<env>/<run>/<variant>/<scene>.json (atomic, resumable).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from adversary.crash.guard_data import read_attack_run
from adversary.crash.redrive import redrive_attack
from adversary.crash.scenes import load_record
from riskmap.evaluation.guard_tables import intervention_totals, markdown_table, print_table, ratio_cell
from riskmap.infra.atomic import write_json
from riskmap.registry import cached_planner

VARIANT_PREFIX = {"alone": "", "always": "guard-always:", "tgat": "guard:", "tgat-anyspeed": "guard:"}


_GUARDED: dict = {}


def anyspeed_guard(inner_spec: str, seed: int, checkpoint: str = ""):
    """The TGAT-triggered guard whose plans act at any speed (speed threshold 0 m/s in every
    family instead of 20 m/s highway / 5 m/s intersection): tests whether the threshold, rather
    than System 1, keeps the guard from acting."""
    from riskmap.guard.guarded import (
        GUARD_CHECKPOINT,
        GuardConfig,
        GuardedHumanDriver,
        GuardedPlanner,
        system2_config,
    )
    from riskmap.guard.predictor import AccidentPredictor
    from riskmap.guard.system2 import DecelerationAgent
    from riskmap.registry import make_planner
    from riskmap.sim.loop.plan import drives_itself

    families = GuardConfig().speed_threshold_mps
    config = GuardConfig(trigger="tgat", speed_threshold_mps={family: 0.0 for family in families},
                         default_speed_threshold_mps=0.0)
    predictor = AccidentPredictor.load(checkpoint or GUARD_CHECKPOINT)
    agent = DecelerationAgent(system2_config(config))
    inner = make_planner(inner_spec, seed=seed)
    if drives_itself(inner):
        return GuardedHumanDriver(predictor, agent, config)
    return GuardedPlanner(inner, predictor, agent, config)


def variant_planner(variant: str, inner_spec: str, seed: int):
    """(planner, SPEC) of `variant`: alone, always, tgat, tgat@CKPT (the TGAT trigger with the
    guard checkpoint CKPT, a path without suffix, instead of the shipped one), tgat-anyspeed or
    tgat-anyspeed@CKPT (`anyspeed_guard`)."""
    base, _, checkpoint = variant.partition("@")
    spec = VARIANT_PREFIX[base] + inner_spec
    if base == "tgat-anyspeed":
        key = (variant, inner_spec, seed)
        if key not in _GUARDED:
            _GUARDED[key] = anyspeed_guard(inner_spec, seed, checkpoint)
        return _GUARDED[key], f"{spec} (plans at any speed{', guard checkpoint ' + checkpoint if checkpoint else ''})"
    if not checkpoint:
        return cached_planner(spec, seed), spec
    from riskmap.guard.guarded import make_guarded

    key = (variant, inner_spec, seed)
    if key not in _GUARDED:
        _GUARDED[key] = make_guarded(base, inner_spec, seed=seed, checkpoint=checkpoint)
    return _GUARDED[key], f"{spec} (guard checkpoint {checkpoint})"


def cell_name(variant: str) -> str:
    """The output folder of a variant: tgat@runs/guard/x/best -> tgat@x-best."""
    base, _, checkpoint = variant.partition("@")
    return f"{base}@{'-'.join(Path(checkpoint).parts[-2:])}" if checkpoint else base


def drive_record(record, attack: dict, variant: str, seed: int) -> dict:
    """One rollout of `attack`'s tracks with the attacked planner wrapped as `variant`
    (`adversary.crash.redrive.redrive_attack`)."""
    planner, spec = variant_planner(variant, attack["planner"], seed)
    return {"variant": variant, **redrive_attack(record, attack, planner, spec)}


def run(attack_dirs: list[Path], out: Path, variants: list[str], count: int) -> None:
    for attack_dir in attack_dirs:
        attack_run = read_attack_run(attack_dir)
        for name in attack_run.names[:count]:
            attack = json.loads((attack_run.path / "attacks" / f"{name}.json").read_text())
            if attack.get("status") != "ok":
                continue
            record = None
            for variant in variants:
                path = out / attack["scene"]["env_id"] / attack_run.path.name / cell_name(variant) / f"{name}.json"
                if path.exists():
                    continue
                record = record or load_record(attack_run.scenes / f"{name}.npz")
                result = drive_record(record, attack, variant, attack_run.seed)
                result.update({"scene": name, "attack_collision": bool(attack["collision"]),
                               "attack_run": str(attack_run.path)})
                write_json(path, result)
                print(f"{attack_run.path.name} {name} {variant}: collision {result['collision']}", flush=True)


def summarise(out: Path) -> list[dict]:
    """One row per (env, attack run, variant) over the scenes that every variant of that run
    finished, so that the variants are compared on the same scenes."""
    rows = []
    cells = sorted(p for p in out.glob("*/*/*") if p.is_dir())
    common: dict = {}
    for cell in cells:
        names = {p.stem for p in cell.glob("scene_*.json")}
        key = cell.parent
        common[key] = names if key not in common else common[key] & names
    for cell in cells:
        env_id, run_name, variant = cell.relative_to(out).parts
        records = [json.loads((cell / f"{name}.json").read_text()) for name in sorted(common[cell.parent])]
        if not records:
            continue
        rows.append({
            "env": env_id, "attack_run": run_name, "variant": variant, "scenes": len(records),
            "collisions": sum(r["collision"] for r in records),
            "collision_rate": float(np.mean([r["collision"] for r in records])),
            "collisions_any": sum(r["collision_any"] for r in records),
            "progress_m": float(np.mean([r["progress_m"] for r in records])),
            **intervention_totals(records),
        })
    return rows


COLUMNS = ("env", "attack run", "variant", "scenes", "collisions with adversary", "rate", "any collision",
           "progress (m, 6 s)", "frames", "interventions", "BDI ratio")


def markdown(rows: list[dict]) -> str:
    return markdown_table(COLUMNS, [(r["env"], r["attack_run"], r["variant"], r["scenes"], r["collisions"],
                                     f"{r['collision_rate']:.2f}", r["collisions_any"], f"{r['progress_m']:.1f}",
                                     r["frames"] or "–", r["interventions"] or 0, ratio_cell(r))
                                    for r in rows])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--attacks", type=Path, action="append", default=[],
                        help="an `adversary attack --out` directory (repeat)")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--variants", default="alone,always,tgat")
    parser.add_argument("--count", type=int, default=60, help="first COUNT attack records of each run")
    parser.add_argument("--table", type=Path, default=None, help="write PREFIX.json and PREFIX.md")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    run(args.attacks, args.out, args.variants.split(","), args.count)
    print_table(summarise(args.out), markdown, args.table)


if __name__ == "__main__":
    main()
