"""`adversary scenes` and `adversary attack`: record held-out attack scenes, attack them all.

Scenes: DIR/scene_NNNNN.npz (+ .json) and DIR/index.json, written by the one scene writer over
a sweep of highway-env episodes or of recorded vehicles (`adversary.crash.scene_sweep`).

Attacks: OUT/attacks/<scene>.json, one per scene, written atomically as soon as its batch
finishes (`--batch-size` scenes are optimised together: one Adam step updates all of them, which
costs little more than one scene on a CPU; batches are fixed slices of the scene list); `--resume`
runs again only the batches with a scene not there, and writes only the missing records.
OUT/summary.json and OUT/table.md aggregate them (denominators included); plans that failed the
planner contract's checks are summed in the summary (`implausible_plans`, the scenes with any,
the first one's problems) and named in a line under the table when there are any. With `--workers K`
scenes run in a process pool; every scene's random draws depend only on (seed, scene), so results
do not depend on K.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from adversary.crash.attack import AttackConfig, attack_records, load_models
from adversary.crash.scene_sweep import INDEX, read_index
from rasterize.errors import InputError
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.formats import Format
from riskmap.infra.parallel import run_parallel
from riskmap.infra.rundir import claim_out_dir
from riskmap.sim.loop.plan_checks import implausible_note, summarise_implausible
from riskmap.sim.records.record import current_names


def scenes_family(scenes_dir: Path) -> str:
    """The traffic-model family of a scene directory: recorded scenes name theirs, simulated ones
    have their env's."""
    from rasterize.config import family_of_env

    index = read_index(Path(scenes_dir))
    try:
        return index.get("family") or family_of_env(index["env_id"])
    except (KeyError, AttributeError):
        raise InputError(f"--scenes {scenes_dir} holds no readable scene index ({INDEX}); make one with "
                         "`adversary scenes`") from None


def check_traffic_family(traffic: Path, scenes_dir: Path) -> None:
    """A traffic model trained on another family (its sidecar says which) would generate
    futures for roads and speeds it never saw: refused before any work."""
    from adversary.crash.train_traffic import traffic_model_family

    trained, wanted = traffic_model_family(Path(traffic)), scenes_family(scenes_dir)
    if trained is not None and trained != wanted:
        raise InputError(f"--traffic-model {traffic} was trained on {trained} windows, the scenes in "
                         f"{scenes_dir} are {wanted}; pass checkpoints/crash_traffic_{wanted} or train one "
                         "with `adversary train-traffic`")


def scene_paths(scenes_dir: Path, count: int) -> list[Path]:
    scenes_dir = Path(scenes_dir)
    index = read_index(scenes_dir)
    if len(index["scenes"]) < count:
        raise InputError(f"--scenes {scenes_dir} holds {len(index['scenes'])} scenes, fewer than --count "
                         f"{count}; record more with `adversary scenes ... --resume`")
    return [scenes_dir / f"{name}.npz" for name in index["scenes"][:count]]


_MODELS: dict = {}


def _attack_batch(paths: list[str], planner_spec: str, config: AttackConfig, seed: int, traffic: str,
                  selectors: str | None, panels: list[str | None]) -> list[dict]:
    """Worker entry: a batch of scenes, never raises (an error becomes every scene's record)."""
    import torch

    from adversary.crash.scenes import load_record
    from riskmap.registry import cached_planner

    torch.set_num_threads(1)
    started = time.perf_counter()
    names = [Path(p).stem for p in paths]
    try:
        key = (traffic, selectors)
        if key not in _MODELS:
            _MODELS[key] = load_models(Path(traffic), Path(selectors) if selectors else None)
        records = [load_record(Path(p)) for p in paths]
        seeds = [int(np.random.SeedSequence([seed, r.scene.scene_seed, r.scene.episode]).generate_state(1)[0])
                 for r in records]
        planner = cached_planner(planner_spec, seed)
        results = attack_records(records, _MODELS[key], planner, planner_spec, config, seeds,
                                 [Path(p) if p else None for p in panels])
    except Exception as error:  # noqa: BLE001  (a failing batch is recorded; the run goes on)
        message = (f"{type(error).__name__}: {error}".splitlines() or [""])[0][:500]
        seconds = (time.perf_counter() - started) / len(paths)
        results = [{"status": "error", "collision": False, "error": message, "seconds": seconds}
                   for _ in paths]
    return [{"name": name, **result} for name, result in zip(names, results)]


def _attack_batch_of(args: tuple) -> list[dict]:
    """`_attack_batch(*args)`: the one-argument form the parallel runner calls."""
    return _attack_batch(*args)


def _interval(successes: int, trials: int) -> list[float] | None:
    """The 95% Wilson interval [lo, hi] of a rate (None without trials)."""
    from riskmap.infra.stats import wilson

    ci = wilson(successes, trials)
    return None if ci is None else [round(ci["lo"], 4), round(ci["hi"], 4)]


def summarise(records: list[dict]) -> dict:
    from riskmap.sim.records.failures import summarise_failures

    ok = [r for r in records if r["status"] == "ok"]
    hits = [r for r in ok if r["collision"]]
    n = len(records)

    def rate(items, key):
        # results written before the judge's names were fixed say ego_off_road (current_names)
        return sum(bool(current_names(r["metrics"])[key]) for r in items) / len(items) if items else None

    kin = [r["metrics"]["kinematic_value_mps"] for r in hits if r["metrics"]["kinematic_value_mps"] is not None]
    solved = [r["metrics"]["solution_found"] for r in hits if r["metrics"]["solution_found"] is not None]
    types: dict[str, int] = {}
    for r in hits:
        types[r["metrics"]["collision_type"]] = types.get(r["metrics"]["collision_type"], 0) + 1
    seconds = [r["seconds"] for r in records if r["status"] != "error"]
    return {
        "scenes": n, "attacked": len(ok),
        "no_candidate": sum(r["status"] == "no_candidate" for r in records),
        "errors": sum(r["status"] == "error" for r in records),
        "collisions": len(hits),
        "collision_rate": len(hits) / n if n else None,       # over every scene: a scene without a
        "collision_ci95": _interval(len(hits), n),            # candidate counts as a miss
        "adversary_off_road_rate": rate(ok, "adversary_off_road"),
        "adversary_off_road_ci95": _interval(round((rate(ok, "adversary_off_road") or 0) * len(ok)), len(ok)),
        "other_off_road_rate": rate(ok, "other_off_road"),
        "ego_off_road_rate": rate(ok, "off_road"),
        "kinematic_value_mps": float(np.mean(kin)) if kin else None,
        "solution_rate": float(np.mean(solved)) if solved else None,
        "collision_types": types,
        # valid, avoidable, at-fault: the failures that count (riskmap.sim.records.failures)
        "failures": summarise_failures([r["metrics"].get("failure") for r in hits], n),
        "seconds_per_scene_median": float(np.median(seconds)) if seconds else None,
        "seconds_per_scene_mean": float(np.mean(seconds)) if seconds else None,
        "iterations_mean": float(np.mean([r["generation"]["iterations"] for r in ok])) if ok else None,
        "rollouts_mean": float(np.mean([r["timing"]["rollouts"] for r in ok])) if ok else None,
        "replans_mean": float(np.mean([r["generation"]["replans"] for r in ok])) if ok else None,
        # over every drive of the scenes that ran (implausible_plan_episodes: scenes with any)
        **summarise_implausible([r for r in records if r["status"] != "error"], lambda r: f"on {r['name']}"),
    }


def table_row(label: str, s: dict) -> str:
    """One row of TABLE_HEADER: the failures that count first, the raw collision rate beside them;
    valid / avoidable / fault columns count collisions (– when no record could be classified)."""
    from riskmap.sim.records.failures import summarise_failures

    def pct(v):
        return "–" if v is None else f"{100 * v:.1f}"

    def num(v, fmt="{:.2f}"):
        return "–" if v is None else fmt.format(v)

    def interval(ci):
        return "" if not ci else f" [{100 * ci[0]:.0f}–{100 * ci[1]:.0f}]"

    f = s.get("failures") or summarise_failures([None] * s["collisions"], s["scenes"])

    def share(k):
        return "–" if k is None or f["collisions"] == f["unknown"] else f"{k}"

    return (f"| {label} | {f['counted']}/{s['scenes']} ({pct(f['counted_rate'])}"
            f"{interval(f.get('counted_ci95'))}) | {s['collisions']}/{s['scenes']} ({pct(s['collision_rate'])}"
            f"{interval(s.get('collision_ci95'))}) | {share(f['valid'])} | {share(f['avoidable'])} | "
            f"{share(f['at_fault'])} / {share(f['struck_from_behind'])} / {share(f['side'])} | "
            f"{pct(s['adversary_off_road_rate'])}{interval(s.get('adversary_off_road_ci95'))} | "
            f"{pct(s['other_off_road_rate'])} | "
            f"{num(s['kinematic_value_mps'])} | {pct(s['solution_rate'])} | "
            f"{num(s['seconds_per_scene_median'], '{:.1f}')} |")


TABLE_HEADER = ("| run | valid avoidable at-fault (%, 95% CI) | collision (%, 95% CI) | valid | avoidable | "
                "at fault / struck from behind / side | adv off-road % | other off-road % | kinematic value m/s | "
                "solution % | s/scene |\n|---|---|---|---|---|---|---|---|---|---|---|")


def implausible_line(label: str, s: dict) -> str:
    """The line under the table when the planner made implausible plans ("" otherwise)."""
    return implausible_note({label: (s, s["scenes"])}, unit="scenes")


def _paragraph(text: str) -> str:
    return "\n" + text if text else ""


def _attack_run_v1(meta: dict) -> dict:
    """An attack run.json from before versions were kept: it left out the options at the values
    every run had before they existed (`replan_hz` at its default, `validity_terms` off: the
    paper's loss)."""
    config = {"replan_hz": AttackConfig.replan_hz, "validity_terms": False, **meta.get("config", {})}
    return {**meta, "config": config}


# An attack run's settings (run.json); a resumed run compares them upgraded.
ATTACK_RUN_FORMAT = Format("CRASH attack run's settings", (_attack_run_v1,))


# Under every written table: where its columns are defined.
TABLE_NOTE = ("Columns: valid avoidable at-fault = the failures that count, over every scene; valid, avoidable "
              "and fault classes count wins (riskmap/sim/records/failures.py; "
              "docs/guide/failures-that-count.md); solution % = STRIVE's hindsight check.")


def run_attacks(planner_spec: str, scenes_dir: Path, count: int, config: AttackConfig, seed: int,
                out: Path, traffic: Path, selectors: Path | None, workers: int = 1, resume: bool = False,
                panels: int = 0, progress: bool = True, batch_size: int = 8) -> dict:
    from adversary.crash.scenes import load_record
    from riskmap.registry import display_name, make_planner

    out = Path(out)
    paths = scene_paths(scenes_dir, count)
    for path in paths:                             # a damaged scene fails here, before any work
        load_record(path)
    make_planner(planner_spec, seed=seed)          # a bad SPEC fails here, before any work
    load_models(Path(traffic), Path(selectors) if selectors else None)
    check_traffic_family(Path(traffic), scenes_dir)
    attacks_dir = out / "attacks"
    meta = {"planner": planner_spec, "scenes": str(scenes_dir), "count": count, "config": asdict(config),
            "seed": seed, "traffic_model": str(traffic), "selector_model": str(selectors) if selectors else None}
    claim_out_dir(out, holds="attacks", marker="attacks", resume=resume, settings_file="run.json",
                  settings=meta, may_change=("count",), file_format=ATTACK_RUN_FORMAT)
    attacks_dir.mkdir(parents=True, exist_ok=True)
    finished = {p.stem for p in paths if (attacks_dir / f"{p.stem}.json").exists()}
    panels_dir = out / "panels"

    def panel_for(i: int) -> str | None:
        return str(panels_dir / f"{paths[i].stem}.png") if i < panels else None

    # Batches are fixed slices of the scene list: a scene's numbers depend on the scenes optimised
    # with it (float rounding of the batched model, the losses kept by the first), so a resumed run
    # batches every scene as an uninterrupted one does. A batch that a kill cut off runs whole
    # again; only its missing records are written.
    batches = [chunk for chunk in (paths[i:i + batch_size] for i in range(0, len(paths), batch_size))
               if any(p.stem not in finished for p in chunk)]
    todo = [p for chunk in batches for p in chunk if p.stem not in finished]
    args = [([str(p) for p in chunk], planner_spec, config, seed, str(traffic),
             str(selectors) if selectors else None, [panel_for(paths.index(p)) for p in chunk])
            for chunk in batches]
    done = 0

    def save(results: list[dict]) -> None:
        nonlocal done
        for result in results:
            if result["name"] in finished:
                continue          # kept from the killed run (the same record)
            write_json(attacks_dir / f"{result['name']}.json", result)
            done += 1
            if progress:
                print(f"[{done}/{len(todo)}] {result['name']}: {result['status']}"
                      f"{' COLLISION' if result['collision'] else ''} ({result['seconds']:.1f} s)", flush=True)

    if panels:
        panels_dir.mkdir(parents=True, exist_ok=True)
    for _, results in run_parallel(_attack_batch_of, args, workers):
        save(results)
    records = [json.loads((attacks_dir / f"{p.stem}.json").read_text()) for p in paths]
    summary = {**meta, "summary": summarise(records)}
    write_json(out / "summary.json", summary)
    label = f"{display_name(planner_spec)} / {config.selector}"
    atomic_write(out / "table.md", lambda f: f.write(
        (TABLE_HEADER + "\n" + table_row(label, summary["summary"]) + "\n\n" + TABLE_NOTE + "\n"
         + _paragraph(implausible_line(label, summary["summary"]))).encode()))
    return summary
