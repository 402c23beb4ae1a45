"""Execution backends of a campaign: `run_job` over the one parallel runner.

`local` runs `adversary.campaign.job.run_job` in a process pool (or inline for one worker); `ray`
runs the very same function as Ray tasks on a cluster (`address`) or a local Ray instance
(`riskmap.infra.parallel`). Both yield (job, result) pairs in completion order; the campaign writes
each result as it arrives. A job's own errors become error records inside run_job; a Ray worker
that dies under a job fails only that job (an error record); a local pool worker that dies breaks
the pool, so the campaign stops there and `--resume` continues with the unfinished jobs.
"""

from __future__ import annotations

from collections.abc import Iterator

from adversary.campaign.job import Job, error_result, run_job
from riskmap.infra.parallel import BACKENDS, run_parallel

__all__ = ["BACKENDS", "run_jobs"]


def run_jobs(jobs: list[Job], backend: str, workers: int, address: str | None = None
             ) -> Iterator[tuple[Job, dict]]:
    return run_parallel(run_job, jobs, workers, backend, address, on_lost=error_result)
