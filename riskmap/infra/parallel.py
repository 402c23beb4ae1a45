"""The one parallel runner: apply a function to items in worker processes or as Ray tasks.

`run_parallel(fn, items, workers, backend)` yields `(item, result)` pairs in completion order, so
callers write each result as it arrives (an interrupted run keeps what finished). `fn` must be a
picklable top-level function; results must not depend on which worker ran an item or when.

- `local`, one worker: inline, in this process (debuggable, no pickling).
- `local`, several: a `spawn` process pool. spawn, not fork: the parent may hold torch/OpenMP
  threads that a fork would copy half-made. A pool worker that dies breaks the whole pool
  (concurrent.futures' design): the error propagates and `--resume` continues.
- `ray`: Ray tasks on a cluster (`address`) or a local Ray instance. An item whose worker or
  node dies under it is submitted again (up to `RAY_ATTEMPTS` times in all; each loss and retry
  is logged on stderr, as is a node that leaves the cluster); its result is yielded once, when an
  attempt finishes. An item that fails every attempt, or whose function raised, fails alone:
  `on_lost(item, error)` turns it into a result (without it, the error propagates).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from rasterize.errors import InputError

BACKENDS = ("local", "ray")
RAY_ATTEMPTS = 3      # tries per item when its Ray worker or node dies under it


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


def _log(message: str) -> None:
    print(f"ray: {message}", file=sys.stderr, flush=True)


def _alive_nodes(ray) -> dict[str, str]:
    return {node["NodeID"]: node.get("NodeManagerAddress", "?") for node in ray.nodes()
            if node.get("Alive")}


def _log_lost_nodes(before: dict[str, str], now: dict[str, str]) -> dict[str, str]:
    """Log each node of `before` missing from `now` (node id -> address); returns `now`."""
    for node in before.keys() - now.keys():
        _log(f"node {node[:12]} at {before[node]} lost; {len(now)} node(s) left, its running "
             "items are retried")
    return now


def _run_ray(fn, items: list, workers: int, address: str | None, on_lost) -> Iterator[tuple[Any, Any]]:
    started_here = init_ray(workers, address)
    import ray

    # Ray's own retries are off: this loop retries, so that every loss is logged and counted.
    remote = ray.remote(num_cpus=1, max_retries=0)(fn)
    pending = {remote.remote(item): (item, 1) for item in items}
    nodes = _alive_nodes(ray)
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
            nodes = _log_lost_nodes(nodes, _alive_nodes(ray))
            for ref in done:
                item, attempt = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayTaskError as error:      # the function itself raised
                    if on_lost is None:
                        raise
                    result = on_lost(item, error)
                except ray.exceptions.RayError as error:          # its worker or node died
                    if attempt < RAY_ATTEMPTS:
                        why = " ".join(str(error).split())[:160]
                        _log(f"item {_name(item)} lost ({type(error).__name__}: {why}); "
                             f"retrying, attempt {attempt + 1} of {RAY_ATTEMPTS}")
                        pending[remote.remote(item)] = (item, attempt + 1)
                        continue
                    _log(f"item {_name(item)} lost {RAY_ATTEMPTS} times; recorded as failed")
                    if on_lost is None:
                        raise
                    result = on_lost(item, error)
                yield item, result
    finally:
        for ref in pending:
            ray.cancel(ref)
        if started_here:
            ray.shutdown()


def _name(item) -> str:
    """How a log line names an item: its `job_id` where it has one."""
    return str(getattr(item, "job_id", item))[:80]
