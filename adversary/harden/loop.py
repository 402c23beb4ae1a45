"""`adversary harden`: fine-tune a risk-map planner on the attacks that beat it, round after round.

Round r (1 ... R) starts from the planner of round r - 1 (round 0: `--checkpoint`):

    RUN/round_r/attack/     CRASH (MAM+ASM) against it on the training scenes (`adversary attack`)
    RUN/round_r/windows/    each successful attack as training windows (`adversary.harden.windows`)
    RUN/round_r/search/     with --search-templates: NSGA-II (`adversary search`) against it, one
                            run per template; every collided scenario as windows too
                            (`adversary.harden.search_windows`, shards search_<template>_<key>)
    RUN/round_r/data/       those of rounds 1 ... r mixed with natural windows (`adversary.harden.dataset`)
    RUN/round_r/train/      `riskmap train` from round r - 1's weights on that data
    RUN/round_r/planner.*   its last epoch, with the original's sampler and planning settings (the round's planner)

and the judgement, on held-out scenes with attacks optimised afresh against every round's planner
(never replayed from another round's):

    RUN/eval/round_r/attack/   CRASH against round r's planner (r = 0: the original)
    RUN/eval/round_r/natural/  natural traffic: closed loop (`riskmap evaluate`, or recordings with
                               `riskmap evaluate --commonroad`) and open-loop ADE on the
                               original's validation windows (ade.json)

RUN/rounds.json sums every round up as it finishes. Every stage writes atomically and is
resumable: `--resume` goes on from the last file written (a stage's own resume: attacks by
scene, windows by attack, training by epoch, evaluations by episode).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path

from rasterize.errors import InputError
from riskmap.infra.atomic import write_json
from riskmap.infra.rundir import claim_out_dir

SETTINGS = "harden.json"
ROUNDS = "rounds.json"
KEEP = ("last", "best")          # HardenConfig.keep


@dataclass(frozen=True)
class HardenConfig:
    """A hardening run. Seconds, metres; shares in [0, 1)."""

    checkpoint: str                  # the risk-map planner to harden (round 0)
    scenes: str                      # training attack scenes (`adversary scenes`)
    natural: str                     # the natural dataset the checkpoint was trained on
    out: str
    rounds: int = 2
    count: int = 60                  # training scenes attacked per round
    natural_share: float = 0.5       # share of natural windows in a round's training windows
    epochs: int = 3                  # fine-tuning epochs per round
    lr: float = 1e-4
    uncertainty_weight: float | None = None   # v of the IRL loss; None: the checkpoint's
    risk_goal_threshold: float | None = None   # TrainConfig.risk_goal_threshold of the fine-tunes; None: none
    demonstration: str = "safest"    # which collision-free alternative demonstrates (HardenWindowConfig.choice)
    replan_every: int = 50           # k of the attack (a risk-map rollout costs ~8 IDM ones)
    seed: int = 0
    eval_scenes: str | None = None   # held-out attack scenes (the judgement); None: none
    eval_count: int = 40
    natural_env: str | None = None   # closed-loop natural traffic: a highway-env family ...
    natural_episodes: int = 20
    natural_seed: int = 2000
    natural_commonroad: tuple[str, ...] = ()   # ... or held-out recordings
    ade_windows: int = 100           # open-loop ADE on this many of the original's validation windows
    traffic_model: str | None = None     # default: checkpoints/crash_traffic_<family>
    selector_model: str | None = None    # default: checkpoints/crash_selector_<family>
    workers: int = 1
    batch_size: int = 8              # scenes optimised together in an attack
    search_templates: tuple[str, ...] = ()   # NSGA-II templates searched each round; (): CRASH only
    search_pop: int = 12             # evaluations per generation of a round's search
    search_gen: int = 6              # its generations (budget pop × gen per template)
    # Cap on the search windows' share of a round's attack windows (CRASH + search); None: no cap.
    # A round's searches can find many more failures than CRASH (717 windows against 122 on
    # highway), and a planner trained mostly on them learns to hang back.
    search_share: float | None = None
    # Which epoch of a round's fine-tune becomes its planner: "last", or "best" by open-loop ADE on
    # the natural validation windows (the original's split). Fine-tuning on attack windows pulls
    # the planner away from ordinary driving epoch by epoch; "best" stops where natural driving
    # was still kept, the early stopping the no-regression bounds ask for.
    keep: str = "last"

    def __post_init__(self) -> None:
        object.__setattr__(self, "natural_commonroad", tuple(self.natural_commonroad))
        object.__setattr__(self, "search_templates", tuple(self.search_templates))
        for name in ("rounds", "count", "epochs", "eval_count", "natural_episodes", "workers", "batch_size",
                     "replan_every", "search_pop", "search_gen"):
            if getattr(self, name) < 1:
                raise InputError(f"--{name.replace('_', '-')} must be at least 1")
        if not 0.0 <= self.natural_share < 1.0:
            raise InputError(f"--natural-share {self.natural_share} must be in [0, 1)")
        if self.search_share is not None and not 0.0 <= self.search_share < 1.0:
            raise InputError(f"--search-share {self.search_share} must be in [0, 1)")
        if self.natural_env and self.natural_commonroad:
            raise InputError("--natural-env and --natural-commonroad: give one of them")
        from adversary.harden.windows import DEMONSTRATIONS

        if self.demonstration not in DEMONSTRATIONS:
            raise InputError(f"--demonstration {self.demonstration!r} must be one of {', '.join(DEMONSTRATIONS)}")
        if self.keep not in KEEP:
            raise InputError(f"--keep {self.keep!r} must be one of {', '.join(KEEP)}")
        if not 0 < self.lr < float("inf"):
            raise InputError(f"--lr must be a positive number, got {self.lr}")
        from adversary.search.scenarios import get_template

        for template in self.search_templates:
            get_template(template)


def round_dir(out: Path, r: int) -> Path:
    return Path(out) / f"round_{r}"


def planner_path(config: HardenConfig, r: int) -> Path:
    """Round r's planner checkpoint (without suffix); round 0 is the original."""
    if r == 0:
        return Path(config.checkpoint)
    return round_dir(config.out, r) / "planner"


def planner_spec(config: HardenConfig, r: int) -> str:
    return f"riskmap:{planner_path(config, r)}"


def _attack_config(config: HardenConfig):
    from adversary.crash.attack import AttackConfig

    return AttackConfig(selector="crash", replan_every=config.replan_every)


def _models(config: HardenConfig, scenes: Path) -> tuple[Path, Path]:
    from adversary.crash.cli import default_models

    return default_models(scenes, config.traffic_model, config.selector_model)


def attack(config: HardenConfig, r: int, scenes: Path, count: int, out: Path, progress: bool) -> dict:
    """CRASH (MAM+ASM) against round r's planner on `count` of `scenes`, into `out` (resumable)."""
    from adversary.crash.run import run_attacks

    traffic, selectors = _models(config, scenes)
    return run_attacks(planner_spec(config, r), scenes, count, _attack_config(config), config.seed, out, traffic,
                       selectors, workers=config.workers, resume=True, progress=progress,
                       batch_size=config.batch_size)


def attack_windows(config: HardenConfig, r: int, progress: bool) -> list[Path]:
    """Round r's attack records as window shards (ROUND/windows/<scene>.npz + .json); the .json
    is written last, so a shard counts once it is there. Returns the shards' paths."""
    from adversary.crash.scenes import load_record
    from adversary.harden.dataset import write_attack_shard
    from adversary.harden.windows import HardenWindowConfig, hardening_windows
    from riskmap.registry import make_planner

    here = round_dir(config.out, r)
    spec = planner_spec(config, r - 1)
    planner = None
    shards = []
    for path in sorted((here / "attack" / "attacks").glob("*.json")):
        shard = here / "windows" / path.stem
        shards.append(shard)
        if shard.with_suffix(".json").exists():
            continue
        attack_record = json.loads(path.read_text())
        if planner is None:
            planner = make_planner(spec, seed=config.seed)
        record = load_record(Path(config.scenes) / f"{path.stem}.npz")
        made = hardening_windows(record, attack_record, planner, spec, HardenWindowConfig(choice=config.demonstration))
        write_attack_shard(shard, made.scenes, {**made.info, "attack": str(path)})
        if progress and made.scenes:
            print(f"round {r}: {path.stem}: {len(made.scenes)} windows ({made.info.get('demonstration')})",
                  flush=True)
    return shards


def round_search_windows(config: HardenConfig, r: int, progress: bool) -> tuple[list[Path], dict]:
    """Round r's searches against round r - 1's planner (ROUND/search/<template>, seed: the run's
    + r, so never the judgement's) and each collided scenario as a window shard
    (ROUND/windows/search_<template>_<key>); returns the shards and, per template, how many
    scenarios were evaluated and collided."""
    import numpy as np

    from adversary.harden.dataset import write_attack_shard
    from adversary.harden.search_windows import search_failure_windows
    from adversary.harden.windows import HardenWindowConfig
    from adversary.search.guard_data import read_search_run
    from adversary.search.run import SearchConfig, search

    here = round_dir(config.out, r)
    shards, found = [], {}
    for template in config.search_templates:
        out = here / "search" / template
        if not (out / "summary.json").exists():
            search(SearchConfig(planner=planner_spec(config, r - 1), template=template, pop=config.search_pop,
                                gen=config.search_gen, seed=config.seed + r, workers=config.workers),
                   out, resume=out.exists(), progress=progress, frames=False)
        settings, paths = read_search_run(out)
        records = [(path, json.loads(path.read_text())) for path in paths]
        failures = [(path, record) for path, record in records if record.get("feasible") and record.get("collided")]
        found[template] = {"evaluations": len(records), "collisions": len(failures)}
        for path, record in failures:
            shard = here / "windows" / f"search_{template}_{path.stem}"
            shards.append(shard)
            if shard.with_suffix(".json").exists():
                continue
            made = search_failure_windows(settings, np.asarray(record["x"], dtype=np.float64),
                                          HardenWindowConfig(choice=config.demonstration))
            write_attack_shard(shard, made.scenes, {**made.info, "search": str(path)})
            if progress and made.scenes:
                print(f"round {r}: search {template} {path.stem}: {len(made.scenes)} windows", flush=True)
    return shards, found


def earlier_shards(out: Path, r: int) -> list[Path]:
    """The window shards rounds 1 ... r - 1 wrote (ROUND/windows/<name>, committed: .json there),
    round by round: a round trains on every attack so far, not only on its own."""
    return [path.with_suffix("") for k in range(1, r)
            for path in sorted((round_dir(out, k) / "windows").glob("*.json"))]


def fine_tune(config: HardenConfig, r: int, shards: list[Path], progress: bool) -> dict:
    """Round r's training: round r - 1's weights on the mixed data; its last or best epoch
    (`keep`) becomes the round's planner, with the original checkpoint's planning settings."""
    from adversary.harden.dataset import write_round_dataset
    from riskmap.infra.checkpoint import read_sidecar
    from riskmap.training.config import TrainConfig
    from riskmap.training.train import train

    here = round_dir(config.out, r)
    original = read_sidecar(Path(config.checkpoint))
    data = write_round_dataset(here / "data", Path(config.natural), original, shards, config.natural_share,
                               config.seed + r)
    trained = original["train"]
    settings = TrainConfig(
        data=str(here / "data"), out=str(here / "train"), resolution=trained["resolution"],
        uncertainty_weight=(trained["uncertainty_weight"] if config.uncertainty_weight is None
                            else config.uncertainty_weight),
        sigma_x=trained["sigma_x"], sigma_y=trained["sigma_y"], goal_variance=original["irl"]["goal_variance"],
        goal=trained.get("goal", "route"), epochs=config.epochs, batch_size=trained["batch_size"], lr=config.lr,
        horizon=trained["horizon"], val_groups=tuple(data["validation_groups"]), seed=config.seed + r,
        init_checkpoint=str(planner_path(config, r - 1)), predict_s=trained.get("predict_s"),
        risk_goal_threshold=config.risk_goal_threshold,
        timing_head=bool(original["model"].get("timing_head", False)), **spacetime_settings(original))
    resume = (here / "train" / "state.pt").exists()
    train(settings, resume=resume, progress=progress)
    kept = here / "train" / config.keep
    side = round_sidecar(json.loads(kept.with_suffix(".json").read_text()), original,
                         {"round": r, "from": str(planner_path(config, r - 1)), "data": data,
                          "kept": config.keep})
    shutil.copyfile(kept.with_suffix(".safetensors"), here / "planner.safetensors.tmp")
    (here / "planner.safetensors.tmp").replace(here / "planner.safetensors")
    write_json(here / "planner.json", side)
    return {"data": data, "train": side.get("metrics")}


def spacetime_settings(original: dict) -> dict:
    """The TrainConfig fields that make a fine-tune of a space-time planner one too (its steps and
    reach, from its sidecar); none for a spatial planner."""
    from riskmap.planner.st_model import is_spacetime

    if not is_spacetime(original):
        return {}
    st = original["spacetime"]
    return {"planner": "spacetime", "steps": st["steps"], "max_forward": st["max_forward"],
            "max_across": st["max_across"]}


def round_sidecar(trained: dict, original: dict, hardening: dict) -> dict:
    """The round planner's sidecar: the fine-tune's (weights' shapes, training record) with the
    original's sampler and planning settings, so the round's planner turns a risk map into a
    drive exactly as the original does and only the weights differ. (A fresh training sidecar
    names today's default sampler — kinematic timing, gap keeping — while an older original
    plans uniform without gap keeping: comparing the two would measure the sampler.)"""
    side = {**trained, "sampler": original.get("sampler", trained.get("sampler")),
            "planning": original.get("planning"), "hardening": hardening}
    return {k: v for k, v in side.items() if v is not None}


def natural_metrics(config: HardenConfig, r: int, out: Path, progress: bool) -> dict:
    """Round r's planner in natural traffic (closed loop) and open loop on the original's
    validation windows."""
    from adversary.harden.dataset import natural_split
    from riskmap.evaluation.open_loop import evaluate as open_loop
    from riskmap.infra.checkpoint import read_sidecar

    spec = planner_spec(config, r)
    result: dict = {}
    if config.natural_env or config.natural_commonroad:
        from riskmap.evaluation.evaluate import evaluate
        from riskmap.evaluation.sources import EnvSource, RecordingSource

        source = (EnvSource(config.natural_env, config.natural_episodes, seed=config.natural_seed, mode="reactive")
                  if config.natural_env else
                  RecordingSource(tuple(config.natural_commonroad), seed=config.natural_seed, mode="reactive"))
        table = evaluate(source, (spec,), out / "closed_loop", workers=config.workers, resume=True,
                         progress=progress)["planners"][spec]
        result["closed_loop"] = {"episodes": table["episodes"], "collision_rate": table["collided_rate"],
                                 "collisions": round(table["collided_rate"] * table["episodes"]),
                                 **({} if config.natural_env else {"at_fault": table["at_fault"]}),
                                 "distance_m": table["distance_m"]["mean"]}
    ade_path = out / "ade.json"
    if ade_path.exists():
        result["open_loop"] = json.loads(ade_path.read_text())
    else:
        _, val = natural_split(Path(config.natural), read_sidecar(Path(config.checkpoint)))
        indices = _validation_indices(Path(config.natural), val, config.ade_windows)
        result["open_loop"] = open_loop(planner_path(config, r), Path(config.natural), indices=indices,
                                        seed=config.seed)
        write_json(ade_path, result["open_loop"])
    return result


def _validation_indices(natural: Path, val_entries: list[dict], limit: int) -> list[int]:
    """Up to `limit` windows of the natural dataset's validation shards, spread evenly."""
    import numpy as np

    from riskmap.data.dataset import DemoDataset

    dataset = DemoDataset(natural)
    files = {str((natural / e["file"]).resolve()) for e in val_entries}
    shards = {i for i, p in enumerate(dataset.shard_paths) if str(Path(p).resolve()) in files}
    picks = [i for i in range(len(dataset)) if dataset.episode_of(i) in shards]
    return [picks[int(j)] for j in np.unique(np.linspace(0, len(picks) - 1, min(limit, len(picks))).astype(int))]


def check_natural(natural: Path, sidecar: dict) -> None:
    """InputError unless `natural` is a dataset drawn as the checkpoint was trained (its raster)
    whose split the checkpoint's can be rebuilt on."""
    from adversary.harden.dataset import natural_split
    from riskmap.data.dataset import collected_raster_config, load_manifest

    load_manifest(natural)
    drawn = collected_raster_config(natural).to_dict()
    trained = {k: v for k, v in sidecar["raster"].items() if k != "predict_s"}
    if {k: v for k, v in drawn.items() if k != "predict_s"} != trained:
        raise InputError(f"--natural {natural} was collected with another raster than {sidecar['raster']}; "
                         "pass the dataset the checkpoint was trained on")
    natural_split(natural, sidecar)


def judge_round(config: HardenConfig, r: int, progress: bool) -> dict:
    """Round r's planner judged: fresh attacks on the held-out scenes, natural traffic."""
    out = Path(config.out) / "eval" / f"round_{r}"
    result: dict = {}
    if config.eval_scenes:
        result["attack"] = attack(config, r, Path(config.eval_scenes), config.eval_count, out / "attack",
                                  progress)["summary"]
    result.update(natural_metrics(config, r, out / "natural", progress))
    return result


def _settings(config: HardenConfig) -> dict:
    settings = asdict(config) | {"out": str(config.out)}
    if not config.search_templates:        # runs from before the search option resume as they were
        for name in ("search_templates", "search_pop", "search_gen"):
            settings.pop(name)
    if config.keep == "last":              # ... and those from before --keep
        settings.pop("keep")
    if config.search_share is None:        # ... and those from before --search-share
        settings.pop("search_share")
    return settings


def harden(config: HardenConfig, resume: bool = False, progress: bool = True) -> dict:
    """Run (or finish) every round; returns rounds.json's content."""
    from adversary.crash.run import check_traffic_family, scene_paths
    from riskmap.infra.checkpoint import read_sidecar
    from riskmap.registry import make_planner

    out = Path(config.out)
    original = read_sidecar(Path(config.checkpoint))           # a bad input stops here, before any work
    make_planner(planner_spec(config, 0), seed=config.seed)
    check_natural(Path(config.natural), original)
    if config.natural_env:
        from rasterize.config import family_of_env

        family_of_env(config.natural_env)
    if config.natural_commonroad:
        from riskmap.data.collect_commonroad import scenario_files

        scenario_files(list(config.natural_commonroad), flag="--natural-commonroad")
    scene_paths(Path(config.scenes), config.count)
    traffic, _ = _models(config, Path(config.scenes))
    check_traffic_family(traffic, Path(config.scenes))
    if config.eval_scenes:
        scene_paths(Path(config.eval_scenes), config.eval_count)
    claim_out_dir(out, holds="a hardening run", marker=SETTINGS, resume=resume, settings_file=SETTINGS,
                  settings=_settings(config), may_change=("rounds", "workers"))
    summary = json.loads((out / ROUNDS).read_text()) if resume and (out / ROUNDS).exists() else {"rounds": []}
    done = {entry["round"]: entry for entry in summary["rounds"]}

    def commit(entry: dict) -> None:
        done[entry["round"]] = entry
        summary["rounds"] = [done[k] for k in sorted(done)]
        write_json(out / ROUNDS, summary)

    if 0 not in done:
        commit({"round": 0, "planner": planner_spec(config, 0), "judged": judge_round(config, 0, progress)})
    for r in range(1, config.rounds + 1):
        if r in done:
            continue
        here = round_dir(out, r)
        if progress:
            print(f"round {r}: attacking {planner_spec(config, r - 1)} on {config.count} training scenes", flush=True)
        trained = attack(config, r - 1, Path(config.scenes), config.count, here / "attack", progress)["summary"]
        shards = earlier_shards(out, r) + attack_windows(config, r, progress)
        searched = {}
        if config.search_templates:
            more, searched = round_search_windows(config, r, progress)
            shards += more
        capped = {}
        if config.search_share is not None:
            from adversary.harden.dataset import cap_search_shards

            shards, capped = cap_search_shards(shards, config.search_share, config.seed + r)
        tuned = fine_tune(config, r, shards, progress)
        commit({"round": r, "planner": planner_spec(config, r), "training_attack": trained,
                **({"training_search": searched} if searched else {}),
                **({"search_cap": capped} if capped else {}), **tuned,
                "judged": judge_round(config, r, progress)})
    return summary


__all__ = ["HardenConfig", "harden", "planner_path", "planner_spec"]
