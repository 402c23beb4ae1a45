"""The one parallel runner: apply a function to items in worker processes or as Ray tasks.

`run_parallel(fn, items, workers, backend)` yields `(item, result)` pairs in completion order, so
callers write each result as it arrives (an interrupted run keeps what finished). `fn` must be a
picklable top-level function; results must not depend on which worker ran an item or when.

- `local`, one worker: inline, in this process (debuggable, no pickling).
- `local`, several: a `spawn` process pool. spawn, not fork: the parent may hold torch/OpenMP
  threads that a fork would copy half-made. A pool worker that dies breaks the whole pool
  (concurrent.futures' design): the error propagates and `--resume` continues.
- `ray`: Ray tasks on a cluster (`address`) or a local Ray instance. A worker that dies under an
  item fails only that item: `on_lost(item, error)` turns it into a result (without it, the
  error propagates).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

from rasterize.errors import InputError

BACKENDS = ("local", "ray")


def run_parallel(fn: Callable[[Any], Any], items: Iterable, workers: int = 1, backend: str = "local",
                 address: str | None = None, initializer: Callable[[], None] | None = None,
                 on_lost: Callable[[Any, BaseException], Any] | None = None
                 ) -> Iterator[tuple[Any, Any]]:
    """(item, fn(item)) for every item, in completion order (see the module docstring)."""
    items = list(items)
    if workers < 1:
        raise InputError(f"--workers {workers}: must be at least 1")
    if backend == "local":
        return _run_local(fn, items, workers, initializer)
    if backend == "ray":
        return _run_ray(fn, items, workers, address, on_lost)
    raise InputError(f"--backend {backend!r} is unknown; use one of {', '.join(BACKENDS)}")


def _run_local(fn, items: list, workers: int, initializer) -> Iterator[tuple[Any, Any]]:
    if workers <= 1 or len(items) <= 1:
        if initializer is not None:
            initializer()
        for item in items:
            yield item, fn(item)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(min(workers, len(items)), mp_context=multiprocessing.get_context("spawn"),
                             initializer=initializer) as pool:
        futures = {pool.submit(fn, item): item for item in items}
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
    from riskmap.infra.provenance import PACKAGE_ROOT

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


def _run_ray(fn, items: list, workers: int, address: str | None, on_lost) -> Iterator[tuple[Any, Any]]:
    started_here = init_ray(workers, address)
    import ray

    remote = ray.remote(num_cpus=1)(fn)
    pending = {remote.remote(item): item for item in items}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                item = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayError as error:
                    if on_lost is None:
                        raise
                    result = on_lost(item, error)
                yield item, result
    finally:
        for ref in pending:
            ray.cancel(ref)
        if started_here:
            ray.shutdown()
