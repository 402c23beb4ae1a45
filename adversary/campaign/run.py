"""`adversary stress-test`: run every job of a campaign into a result store, resumably.

A job is finished once its record exists in DIR/records; `--resume` runs only the others. The
campaign refuses to resume into a DIR made with another config. `max_jobs` stops after that
many new jobs (a campaign split over several sittings; the tests use it to stand for a kill).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from adversary.campaign.backends import run_jobs
from adversary.campaign.config import CampaignConfig
from adversary.campaign.store import ResultStore
from rasterize.errors import InputError
from riskmap.infra.atomic import write_json
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import lock_out_dir


@dataclass(frozen=True)
class RunOptions:
    backend: str = "local"            # local | ray
    workers: int = 1
    address: str | None = None        # Ray cluster address; None: a local Ray instance
    resume: bool = False
    max_jobs: int | None = None       # stop after this many new jobs
    progress: bool = True


def check_planners(config: CampaignConfig) -> None:
    """Every planner SPEC resolves (checkpoints load) before any job starts."""
    from riskmap.registry import make_planner

    for spec in config.planners:
        make_planner(spec, seed=config.seed)


def check_attack_models(config: CampaignConfig) -> None:
    """Every checkpoint an attack needs on its scenario families exists (e.g. the crash attack's
    traffic models and selectors) before any job starts."""
    envs = sorted(set(config.env_ids()))
    for attack, (_name, params) in zip(config.attacks, config.attack_params().values()):
        if hasattr(params, "check_envs"):
            params.check_envs([env for env in envs if attack.applies_to(env)])


def _campaign_meta(config: CampaignConfig, config_text: str | None) -> dict:
    return {"config": config.plain(), "config_text": config_text,
            "jobs": [job.job_id for job in config.jobs()]}


def run_campaign(config: CampaignConfig, out: Path, options: RunOptions = RunOptions(),
                 config_text: str | None = None) -> dict:
    """Run the pending jobs; return counts {total, finished, ran, failed, collided}."""
    from tqdm import tqdm

    out = Path(out)
    meta_path = out / "campaign.json"
    meta = _campaign_meta(config, config_text)
    if meta_path.exists():
        previous = json.loads(meta_path.read_text())
        if not options.resume:
            raise InputError(f"--out {out} already holds a campaign; pass --resume to continue it "
                             "or choose another --out")
        if previous["config"] != meta["config"]:
            raise InputError(f"--out {out} holds a campaign with another config; choose another --out")
    elif out.exists() and any(out.iterdir()) and not options.resume:
        raise InputError(f"--out {out} is not empty; choose a new directory")
    check_planners(config)
    check_attack_models(config)
    lock_out_dir(out)   # one writer per campaign directory (creates it)
    write_json(meta_path, {**meta, **provenance()})
    store = ResultStore(out)
    jobs = config.jobs()
    done = store.finished()
    pending = [job for job in jobs if job.job_id not in done]
    if options.max_jobs is not None:
        pending = pending[: options.max_jobs]
    finished = [r for r in store.records() if r["job_id"] in {j.job_id for j in jobs}]
    collided = sum(bool(r.get("collided")) for r in finished)
    failed = sum(r["status"] != "ok" for r in finished)
    ran = 0
    bar = tqdm(total=len(jobs), initial=len(finished), disable=not options.progress,
               desc=f"stress-test {config.name}", unit="job")
    try:
        for _job, result in run_jobs(pending, options.backend, options.workers, options.address):
            record = result["record"]
            store.put(record, result["artifact"])
            ran += 1
            collided += bool(record.get("collided"))
            failed += record["status"] != "ok"
            n = len(finished) + ran
            bar.set_postfix(collision_rate=f"{collided / n:.0%}", failed=failed)
            bar.update(1)
    finally:
        bar.close()
        store.close()
    return {"total": len(jobs), "finished": len(finished) + ran, "ran": ran, "failed": failed,
            "collided": collided}
