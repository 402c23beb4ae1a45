"""The guard's closed-loop table (the paper's Tables 2–3 analogue).

For each scenario family and scene kind (natural traffic, or with a scripted aggressive
neighbour from `riskmap.guard.aggressors`), the same episodes (same seed, same traffic) are
driven by a planner alone, with the deceleration plan always on at high speed
(`guard-always:SPEC`), and with the TGAT-triggered plan (`guard:SPEC`). Reported per cell:
collision rate, progress (distance, mean speed), decision frames, interventions and the BDI
intervention ratio (share of decision frames that System 2 took over), System 1 / System 2 ms;
each collision's class (`riskmap.sim.records.failures`: at fault, avoidable, and for the aggressor's a
valid attack) and how many count.

    .venv/bin/python experiments/guard_eval.py --out out/guard_eval --episodes 8 --seed 100 \
        --inner riskmap --variants alone,always,tgat
    .venv/bin/python experiments/guard_eval.py --out out/guard_eval --table experiments/results/guard/closed_loop

Per episode: OUT/<env>/<scene>/<inner>/<variant>/episode_NNNNNN.json (atomic, resumable).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from riskmap.evaluation.guard_tables import intervention_totals, markdown_table, print_table, ratio_cell
from riskmap.guard.aggressors import AggressorHook
from riskmap.infra.atomic import write_json
from riskmap.infra.stats import wilson
from riskmap.planner.shipped import shipped_spec
from riskmap.registry import make_planner
from riskmap.sim.loop.rollout import DriveHooks
from riskmap.sim.records.failures import classify_run, summarise_failures
from riskmap.sim.worlds.episode import make_env
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

VARIANT_PREFIX = {"alone": "", "always": "guard-always:", "tgat": "guard:"}
EPISODE_S = {"highway-v0": 20.0, "intersection-v0": 16.0}


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def run_cell(out: Path, env_id: str, scene: str, inner: str, variant: str, episodes: int, seed: int) -> None:
    """variant: alone, always, tgat, tgat@X (the TGAT trigger with alert threshold X) or
    tgat@CKPT (with the guard checkpoint CKPT, a path without suffix, and its own threshold)."""
    cell = out / env_id / scene / inner / variant.replace("/", "-")
    base, _, option = variant.partition("@")
    inner_spec = shipped_spec(inner, env_id)
    spec = VARIANT_PREFIX[base] + inner_spec
    threshold = _number(option) if option else None
    if option:
        from riskmap.guard.guarded import GUARD_CHECKPOINT, make_guarded

        planner = make_guarded("tgat", inner_spec, seed=seed, alert_threshold=threshold,
                               checkpoint=GUARD_CHECKPOINT if threshold is not None else option)
    else:
        planner = make_planner(spec, seed=seed)
    env = make_env(env_id, 10)
    config = DriveConfig(env_id, episodes, seed=seed, episode_s=EPISODE_S[env_id])
    for episode in range(episodes):
        path = cell / f"episode_{episode:06d}.json"
        if path.exists():
            continue
        hooks = (AggressorHook(),) if scene == "aggressive" else ()
        driven = {}
        record = drive_episode(env, planner, config, episode,
                               hooks=DriveHooks(on_ready=hooks, on_step=lambda run: driven.update(run=run)))
        if record["collided"] and "run" in driven:       # the collision's class (riskmap.sim.records.failures)
            record["failure"] = classify_run(driven["run"], hooks[0].aggressor if hooks else None)
        guard = getattr(planner, "guard", None)
        record.update({"spec": spec + (f" ({option})" if option else ""), "scene": scene, "variant": variant, "inner": inner,
                       "aggressor": bool(hooks and hooks[0].aggressor is not None)})
        if guard is not None:
            record["guard"] = guard.summary()
            record["guard_log"] = guard.log
        write_json(path, record)
        print(f"{env_id} {scene} {inner} {variant} episode {episode}: collided {record['collided']}", flush=True)


def summarise(out: Path) -> list[dict]:
    rows = []
    for cell in sorted(p for p in out.glob("*/*/*/*") if p.is_dir()):
        records = [json.loads(p.read_text()) for p in sorted(cell.glob("episode_*.json"))]
        if not records:
            continue
        env_id, scene, inner, variant = cell.relative_to(out).parts
        s1 = [x for r in records if "guard" in r for x in r["guard"]["system1_ms"]]
        s2 = [x for r in records if "guard" in r for x in r["guard"]["system2_ms"]]
        hard = sum(r["guard"].get("hard", 0) for r in records if "guard" in r)
        rows.append({
            "env": env_id, "scene": scene, "inner": inner, "variant": variant, "episodes": len(records),
            "collisions": int(sum(r["collided"] for r in records)),
            "collision_ci": wilson(int(sum(r["collided"] for r in records)), len(records)), "hard": hard,
            "collision_rate": float(np.mean([r["collided"] for r in records])),
            # valid, avoidable, at fault (riskmap.sim.records.failures); records from before: unknown
            "failures": summarise_failures([r.get("failure") for r in records if r["collided"]], len(records)),
            "distance_m": float(np.mean([r["distance_m"] for r in records])),
            "mean_speed_mps": float(np.mean([r["mean_speed_mps"] for r in records])),
            **intervention_totals(records),
            "system1_ms_median": float(np.median(s1)) if s1 else None,
            "system2_ms_median": float(np.median(s2)) if s2 else None,
        })
    return rows


COLUMNS = ("env", "scene", "planner", "variant", "episodes", "collisions [95% CI]", "that count [95% CI]",
           "avoidable / at fault / struck from behind / side / valid attack / unknown", "distance (m)",
           "mean speed (m/s)", "frames", "interventions (hard)", "BDI ratio")


def markdown(rows: list[dict]) -> str:
    def cells(r: dict) -> tuple:
        ci = r["collision_ci"]
        f = r.get("failures") or summarise_failures([None] * r["collisions"], r["episodes"])
        fc = f["counted_ci95"]
        classes = (f"{f['avoidable']} / {f['at_fault']} / {f['struck_from_behind']} / {f['side']} / "
                   f"{'–' if f['valid'] is None else f['valid']} / {f['unknown']}")
        return (r["env"], r["scene"], r["inner"], r["variant"], r["episodes"],
                f"{r['collisions']} ({100 * ci['value']:.0f}% [{100 * ci['lo']:.0f}–{100 * ci['hi']:.0f}])",
                f"{f['counted']} ({100 * f['counted_rate']:.0f}% [{100 * fc[0]:.0f}–{100 * fc[1]:.0f}])",
                classes, f"{r['distance_m']:.0f}", f"{r['mean_speed_mps']:.1f}", r["frames"] or "–",
                f"{r['interventions'] or 0} ({r['hard']})", ratio_cell(r))
    return markdown_table(COLUMNS, map(cells, rows))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--envs", default="highway-v0,intersection-v0")
    parser.add_argument("--scenes", default="natural,aggressive")
    parser.add_argument("--inner", default="riskmap", help="comma-separated: idm, riskmap")
    parser.add_argument("--variants", default="alone,always,tgat")
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--table", type=Path, default=None, help="write PREFIX.json and PREFIX.md only")
    args = parser.parse_args()
    if args.table is None:
        for env_id in args.envs.split(","):
            for scene in args.scenes.split(","):
                for inner in args.inner.split(","):
                    for variant in args.variants.split(","):
                        run_cell(args.out, env_id, scene, inner, variant, args.episodes, args.seed)
    print_table(summarise(args.out), markdown, args.table)


if __name__ == "__main__":
    main()
