"""Attacked scenes of a stress-test campaign (`adversary stress-test`) as CommonRoad scenarios.

`adversary export --run CAMPAIGN_DIR` finds a campaign by its store layout (campaign.json and
records/, adversary.campaign.store) and exports each attacked crash job with the writer the attack
runs use (`adversary.export.commonroad.write_commonroad`), as OUT/<job_id>.xml + .json.

A crash job keeps what that needs in its artifact (artifacts/<job_id>.npz, the `export__` arrays
of `adversary.attacks.crash.export_arrays`): the attack record's small fields, the generated
tracks and the ego's drive, and a digest of the scene. The scene itself is recorded again from
the job's scene (`adversary.attacks.crash.rebuild_scene`: the human's highway-env episode driven
again, or the recorded vehicle cut from its recording again) and must match that digest.

Not exported, each listed in OUT/index.json with why: failed jobs, jobs of other attacks (an
episode attack keeps no generated adversary trajectory to write), crash jobs whose scene was not
attacked, crash jobs run before export existed (their artifact lacks the `export__` arrays), and,
with --only-failures, jobs without a collision of the ego from t0 (the judge's failures).
"""

from __future__ import annotations

import json
import shlex
import zipfile
from pathlib import Path

import numpy as np

from rasterize.errors import InputError

OLD_JOB = "not exportable: run before export existed"


def is_campaign(path: Path) -> bool:
    """A campaign directory (adversary.campaign.store's layout), not an attack run."""
    path = Path(path)
    return (path / "campaign.json").is_file() and (path / "records").is_dir()


def _artifact_keys(path: Path) -> set[str]:
    try:
        with np.load(path) as data:
            return set(data.files)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError):
        return set()


def why_not_exportable(record: dict, artifact: Path, only_failures: bool = False) -> str | None:
    """None if the job `record` (artifact at `artifact`) can be exported, else why not (module
    docstring); cheap: reads the artifact's key list only."""
    from adversary.attacks.crash import EXPORT_KEYS

    if record.get("status") != "ok":
        return f"the job failed ({record.get('error')}): no attacked run"
    name = record.get("attack_name")
    if name != "crash":
        return (f"not exportable: a {name} job keeps no generated adversary trajectory (only crash "
                "jobs are exported)")
    if not record.get("attacked"):
        return f"not attacked: {record.get('not_attacked')}"
    if not set(EXPORT_KEYS) <= _artifact_keys(artifact):
        return OLD_JOB
    if only_failures and record.get("failure") is None:
        return "no collision of the ego from t0 (--only-failures)"
    return None


def export_command(campaign_dir: Path, record: dict, artifact: Path) -> str | None:
    """The one command that exports job `record` of campaign `campaign_dir` (None if it cannot be
    exported): the report's job pages show it."""
    if why_not_exportable(record, artifact) is not None:
        return None
    job_id = record["job_id"]
    out = Path(campaign_dir) / "commonroad" / job_id
    return (f"adversary export --run {shlex.quote(str(campaign_dir))} --format commonroad "
            f"--job {shlex.quote(job_id)} --out {shlex.quote(str(out))}")


def job_attack(artifact: Path) -> tuple[dict, str]:
    """(the attack record `write_commonroad` takes, the scene's digest) of an exportable job."""
    with np.load(artifact) as data:
        attack = json.loads(str(data["export__attack_json"]))
        attack["tracks"] = data["export__tracks"].tolist()
        attack["ego_states"] = data["export__ego_states"].tolist()
        digest = str(data["export__scene_sha1"])
    return attack, digest


def _read_campaign(campaign_dir: Path) -> list[dict]:
    """The campaign's finished job records (those of its job list), ordered by job id."""
    try:
        meta = json.loads((campaign_dir / "campaign.json").read_text())
        planned = set(meta["jobs"])
    except (OSError, ValueError, KeyError, TypeError):
        raise InputError(f"--run {campaign_dir}: its campaign.json is unreadable; run `adversary "
                         "stress-test` into a new --out") from None
    records = []
    for path in sorted((campaign_dir / "records").glob("*.json")):
        try:
            record = json.loads(path.read_text())
        except (OSError, ValueError):
            raise InputError(f"--run {campaign_dir}: record {path.name} is unreadable; delete it and run "
                             f"`adversary stress-test --resume --out {campaign_dir}` to run that job "
                             "again") from None
        if isinstance(record, dict) and record.get("job_id") in planned:
            records.append(record)
    return records


def export_campaign(campaign_dir: Path, out: Path, fmt: str = "commonroad", only_failures: bool = False,
                    resume: bool = False, jobs: tuple[str, ...] = (), plot: bool = False,
                    progress: bool = True) -> dict:
    """`adversary export` of a campaign: every exportable job (or those `jobs`) as OUT/<job>.xml +
    OUT/<job>.json (+ .png with `plot`), OUT/export.json the settings, OUT/index.json what was
    exported and what was skipped with why (module docstring). InputError when a named job is not
    the campaign's or when no job can be exported."""
    from adversary.attacks.crash import rebuild_scene, scene_digest
    from adversary.export.commonroad import add_exported, export_target, write_commonroad
    from riskmap.infra.atomic import write_json
    from riskmap.infra.rundir import claim_out_dir

    campaign_dir, out = Path(campaign_dir), export_target(fmt, out)
    records = _read_campaign(campaign_dir)
    if jobs:
        known = {r["job_id"] for r in records}
        missing = [j for j in jobs if j not in known]
        if missing:
            example = sorted(known)[0] if known else "none yet"
            raise InputError(f"--job {missing[0]} is not a finished job of campaign {campaign_dir}; pass "
                             f"a job id of its records/ (e.g. {example}) or the report's job pages")
        records = [r for r in records if r["job_id"] in jobs]
    artifacts = campaign_dir / "artifacts"
    why = {r["job_id"]: why_not_exportable(r, artifacts / f"{r['job_id']}.npz") for r in records}
    if all(why.values()):
        reasons = sorted({w for w in why.values() if w})
        raise InputError(f"--run {campaign_dir}: none of its {len(records)} finished jobs can be exported "
                         f"({'; '.join(reasons)[:300] or 'no finished jobs'}); only attacked crash jobs "
                         "can, of campaigns run since export existed: run one into a new --out")
    if only_failures:
        why.update({r["job_id"]: why_not_exportable(r, artifacts / f"{r['job_id']}.npz", True)
                    for r in records if why[r["job_id"]] is None})
    todo = [r for r in records if why[r["job_id"]] is None]
    settings = {"run": str(campaign_dir), "kind": "campaign", "format": fmt,
                "only_failures": bool(only_failures), "jobs": list(jobs), "plot": bool(plot)}
    claim_out_dir(out, holds="an export", marker=None, resume=resume, settings_file="export.json",
                  settings=settings)
    index = {"exported": [], "skipped": [{"job": r["job_id"], "why": why[r["job_id"]]}
                                         for r in records if why[r["job_id"]] is not None]}
    for i, record in enumerate(todo):
        job_id = record["job_id"]
        entry = {"job": job_id, "xml": f"{job_id}.xml", "sidecar": f"{job_id}.json",
                 "collision": bool(record.get("collided_with_adversary")),
                 "counts": bool((record.get("failure") or {}).get("counts"))}
        if not (resume and (out / f"{job_id}.json").is_file()):
            attack, digest = job_attack(artifacts / f"{job_id}.npz")
            try:
                scene = rebuild_scene(attack)
            except InputError as error:
                index["skipped"].append({"job": job_id,
                                         "why": f"its scene cannot be recorded again: {error}"})
                continue
            if scene_digest(scene) != digest:
                index["skipped"].append({"job": job_id, "why": "its scene, recorded again, differs from the "
                                         "one the job attacked (another simulator or recording?)"})
                continue
            write_commonroad(attack, scene, out, job_id,
                             origin={"campaign": str(campaign_dir), "job_id": job_id})
        add_exported(entry, job_id, out, index, plot, resume)
        if progress:
            print(f"[{i + 1}/{len(todo)}] {job_id} -> {out / entry['xml']}", flush=True)
    write_json(out / "index.json", {**settings, **index})
    return index
