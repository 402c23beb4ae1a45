"""Guard accident windows from black-box search runs (`adversary search`).

Every feasible scenario a search evaluated (OUT/evaluations/<key>.json) is driven again with the
search's own settings (`adversary.search.evaluation.run_scenario`: the same planner, seed and
template, so the same outcome) and its recording is cut into windows by
`riskmap.guard.dataset.extract_windows`, as natural episodes are: a collision (the episode ends at
the first contact) gives windows of the target ending up to 3 s before it; a scenario without one
gives negatives only. The search steered the target towards the ego's failures, so its crashes are
the cut-ins and brake checks the planner did not handle.

Layout: GUARD_DIR/jobs/<split>_search_<template>_<planner>_s<seed>_<key>.npz + .json (atomic;
`--resume` skips those present), next to natural and CRASH windows. With `val_fraction` > 0 the
last share of each run's evaluations (in key order) goes to "val".
"""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from riskmap.guard.dataset import GuardCollectConfig, extract_windows, finished_job, positives_within
from riskmap.guard.features import MAX_HORIZON_S
from riskmap.infra.atomic import write_json, write_npz


def read_search_run(path: Path) -> tuple[dict, list[Path]]:
    """(the run's search config, its feasible evaluation records' paths in key order)."""
    run_json = Path(path) / "run.json"
    try:
        config = json.loads(run_json.read_text())["config"]
    except (OSError, ValueError, KeyError):
        raise InputError(f"--search {path} is not an `adversary search --out` directory (no readable "
                         "run.json); run the search first") from None
    records = sorted((Path(path) / "evaluations").glob("*.json"))
    if not records:
        raise InputError(f"--search {path} holds no evaluations; run or resume the search first")
    return config, records


def search_windows(config: dict, values: np.ndarray, windows_config: GuardCollectConfig,
                   rng: np.random.Generator) -> tuple[dict[str, np.ndarray], dict]:
    """(windows as `extract_windows`, meta) of one scenario of a search run with settings `config`."""
    from adversary.search.evaluation import EvaluationConfig, run_scenario
    from adversary.search.scenarios import get_template

    kept = {}

    def keep(run) -> None:
        kept["run"] = run

    evaluation = EvaluationConfig(config["planner"], config["template"], config["seed"], config["episode_s"],
                                  windows_config.control_hz)
    drive, _ = run_scenario(get_template(config["template"]), values, evaluation, on_reset=keep)
    recorder = kept["run"].recorder
    windows = extract_windows(recorder.tracks(), recorder.ego_id, bool(drive["collided"]),
                              windows_config, rng)
    return windows, {"collided": bool(drive["collided"]), "simulated_s": drive["simulated_s"],
                     "windows": len(windows["ttc_s"]),
                     "positives": positives_within(windows["ttc_s"], MAX_HORIZON_S)}


def export_search(search_dirs: list[Path], out: Path, split: str, val_fraction: float = 0.0,
                  windows_config: GuardCollectConfig = GuardCollectConfig(), resume: bool = False,
                  progress: bool = True) -> list[dict]:
    """Windows of every feasible evaluation under `search_dirs` into `out`; returns the job metas."""
    from tqdm import tqdm

    runs = [(Path(d), *read_search_run(Path(d))) for d in search_dirs]
    todo = []
    for path, config, records in runs:
        feasible = [r for r in records if json.loads(r.read_text()).get("feasible")]
        n_val = round(val_fraction * len(feasible))
        todo += [(path, config, r, "val" if i >= len(feasible) - n_val else split)
                 for i, r in enumerate(feasible)]
    jobs_dir = Path(out) / "jobs"
    metas = []
    for path, config, record_path, job_split in tqdm(todo, disable=not progress, desc="guard data (search)"):
        record = json.loads(record_path.read_text())
        job = (f"{job_split}_search_{config['template'].replace('_', '')}_{config['planner'].split(':')[0]}"
               f"_s{config['seed']}_{record_path.stem}")
        done = finished_job(jobs_dir, job, out, resume)
        if done is not None:
            metas.append(done)
            continue
        rng = np.random.default_rng([zlib.crc32(job.encode()), 13])
        windows, meta = search_windows(config, np.asarray(record["x"], dtype=np.float64), windows_config, rng)
        meta = {"split": job_split, "job": job, "search": str(path), "evaluation": record_path.stem,
                "planner": config["planner"], "template": config["template"], "env_id": "highway-v0",
                "search_collided": bool(record["collided"]), **meta}
        write_npz(jobs_dir / f"{job}.npz", windows)
        write_json(jobs_dir / f"{job}.json", meta)
        metas.append(meta)
    return metas
