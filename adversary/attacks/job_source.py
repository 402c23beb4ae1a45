"""A campaign job's scene as a source: how an attack entry runs against it.

A job's scene is of one kind (adversary.attacks.base: `HIGHWAY`, `RECORDED`), told by the job
itself (a recorded family's job carries its `RecordedScene`). `run_entry` runs any entry against
whatever kind the job has: an entry with `run_job` runs the whole job itself on either kind
(`crash` reads the job's scene); episode hooks are run by the source:

- `HighwayJobs`: a highway-env seed's episode, driven with the hooks
  (`adversary.attacks.episode.drive_with_hooks`);
- `RecordedJobs`: a scene cut from a CommonRoad recording, driven unperturbed with the ego handed
  to the planner at t0 (`adversary.attacks.recorded.natural_recorded_job`); only a baseline's hooks
  may stand for that (`AttackEntry` refuses others).
"""

from __future__ import annotations

from dataclasses import dataclass

from adversary.attacks.base import HIGHWAY, RECORDED, AttackEntry
from rasterize.errors import InputError


@dataclass(frozen=True)
class HighwayJobs:
    kind = HIGHWAY

    def drive_hooks(self, job, factory) -> tuple[dict, bytes | None]:
        from adversary.attacks.episode import drive_with_hooks

        return drive_with_hooks(job, factory)


@dataclass(frozen=True)
class RecordedJobs:
    kind = RECORDED

    def drive_hooks(self, job, factory) -> tuple[dict, bytes | None]:
        from adversary.attacks.recorded import natural_recorded_job

        return natural_recorded_job(job)


def job_source(job) -> HighwayJobs | RecordedJobs:
    """The source of `job`'s scene: a recorded family's job carries its scene."""
    return RecordedJobs() if getattr(job, "scene", None) is not None else HighwayJobs()


def run_entry(entry: AttackEntry, job) -> tuple[dict, bytes | None]:
    """(record fields, artifact) of `entry` run against `job`'s scene (module docstring)."""
    source = job_source(job)
    if source.kind not in entry.scenes:
        raise InputError(f"attack {job.attack_name!r} needs a highway-env world; it cannot run "
                         f"on the recorded family {job.env_id}")
    if entry.run_job is not None:
        return entry.run_job(job)
    return source.drive_hooks(job, entry.factory)
