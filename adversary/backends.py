"""Execution backends: run jobs and yield their results as they finish.

`local` runs `adversary.job.run_job` in a process pool (or inline for one worker); `ray` runs the
very same function as Ray tasks on a cluster (`address`) or a local Ray instance. Both yield
(job, result) pairs in completion order; the campaign writes each result as it arrives.
A job's own errors become error records inside run_job. A Ray worker that dies under a job fails
only that job; a local pool worker that dies breaks the pool (concurrent.futures' design), so
the campaign stops there and `--resume` continues with the unfinished jobs.
"""

from __future__ import annotations

from collections.abc import Iterator

from adversary.job import Job, error_result, run_job
from rasterize.errors import InputError

BACKENDS = ("local", "ray")


def run_local(jobs: list[Job], workers: int) -> Iterator[tuple[Job, dict]]:
    if workers <= 1:
        for job in jobs:
            yield job, run_job(job)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn, not fork: the parent may hold torch/OpenMP threads that a fork would copy half-made.
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {pool.submit(run_job, job): job for job in jobs}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()


def init_ray(workers: int, address: str | None) -> bool:
    """Connect to the Ray cluster at `address`, or start a local one with `workers` CPUs, unless
    Ray is already initialised; True when this call started it (and should shut it down)."""
    try:
        import ray
    except ImportError:
        raise InputError("--backend ray needs Ray: pip install 'riskmap-toolkit[ray]'") from None
    from riskmap.provenance import PACKAGE_ROOT

    if ray.is_initialized():
        return False
    # Workers import this source tree, not whatever copy another path would give them; on a
    # cluster the toolkit must be installed on every node (or shipped with a working_dir).
    runtime_env = {"env_vars": {"PYTHONPATH": str(PACKAGE_ROOT), "OMP_NUM_THREADS": "1"}}
    if address:
        ray.init(address=address, runtime_env=runtime_env, log_to_driver=False)
    else:
        ray.init(num_cpus=max(1, workers), include_dashboard=False, log_to_driver=False,
                 runtime_env=runtime_env)
    return True


def run_ray(jobs: list[Job], workers: int, address: str | None) -> Iterator[tuple[Job, dict]]:
    started_here = init_ray(workers, address)
    import ray

    remote = ray.remote(num_cpus=1)(run_job)
    pending = {remote.remote(job): job for job in jobs}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                job = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayError as error:
                    # run_job never raises: this is the worker dying under the job (a crash, the
                    # memory monitor). Record it against this job; the other tasks go on.
                    result = error_result(job, error)
                yield job, result
    finally:
        for ref in pending:
            ray.cancel(ref)
        if started_here:
            ray.shutdown()


def run_jobs(jobs: list[Job], backend: str, workers: int, address: str | None = None
             ) -> Iterator[tuple[Job, dict]]:
    if backend == "local":
        return run_local(jobs, workers)
    if backend == "ray":
        return run_ray(jobs, workers, address)
    raise InputError(f"--backend {backend!r} is unknown; use one of {', '.join(BACKENDS)}")
