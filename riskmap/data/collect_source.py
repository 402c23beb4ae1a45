"""The one collect driver: demonstration windows of a `CollectSource` into a sharded dataset.

`riskmap collect --env` (`riskmap.data.collect.EnvCollectSource`: highway-env episodes driven
by a demonstrator) and `riskmap collect --from-commonroad`
(`riskmap.data.collect_commonroad.RecordingCollectSource`: recorded vehicles) differ only in
where an item's windows come from. Everything else is here, once:

- claiming `out`: refused when it holds other work, or a dataset unless `--resume`, or a dataset
  of another configuration (`check_out_dir`); one writer at a time (`lock_out_dir`); a run that
  fails before its first shard leaves no directory it created;
- the layout: `shards/episode_NNNNNN.npz` per item (the windows packed by
  `rasterize.scene_io.pack_scenes` and the item's info as JSON), each written atomically;
  `index.json` (shards, windows, groups) and `manifest.json` (config, provenance, counts and the
  source's additions), the manifest first: `--resume` recognises a dataset by it;
- `--resume`: an item whose shard reads back is kept, every other one is (re)done;
- the worker pool (`riskmap.infra.parallel.run_parallel`: inline for one worker) and the
  progress bar.

An item is an int, stable across runs: it names the item's shard, so `--resume` finds finished
work by it. Results must not depend on which process made a shard.
"""

from __future__ import annotations

import functools
import json
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from rasterize.errors import InputError
from rasterize.scene_io import pack_scenes
from riskmap.infra.atomic import write_json, write_npz
from riskmap.infra.parallel import run_parallel
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import holds_work, lock_out_dir

FORMAT_VERSION = 2
SHARD_DIR = "shards"
MANIFEST = "manifest.json"
INDEX = "index.json"


class CollectSource(Protocol):
    """Where a dataset's windows come from."""

    unit: str          # what one item is, for the progress bar ("episode", "vehicle")

    @property
    def config(self) -> Any:
        """Everything that determines the dataset: `to_dict()` is the manifest's `config` (what
        `--resume` compares, but for `episodes`), `seed` the manifest's `seed`."""

    @property
    def label(self) -> str:
        """The progress bar's description."""

    def items(self) -> Sequence[int]:
        """The items, in order; each names its shard (`shard_path`)."""

    def worker_state(self) -> Any:
        """What `windows` needs in this process, made once per worker (a highway-env env)."""

    def windows(self, state: Any, item: int) -> tuple[list, dict]:
        """One item's windows (Scenes) and its info: `episode` (the item), `windows`,
        `simulated_s`, `ego_crashed`, `ego_off_network`, optionally `group`, and anything else."""

    def manifest_extra(self, infos: list[dict]) -> dict | None:
        """What the finished manifest adds, from every item's info (in item order)."""


def shard_path(out: Path, episode: int) -> Path:
    return out / SHARD_DIR / f"episode_{episode:06d}.npz"


def write_episode_shard(out: Path, windows: list, info: dict) -> None:
    arrays = pack_scenes(windows) if windows else {}
    arrays["episode_info"] = np.frombuffer(json.dumps(info, sort_keys=True).encode(), np.uint8)
    write_npz(shard_path(out, info["episode"]), arrays)


def read_episode_info(path: Path) -> dict | None:
    """The info of a finished shard, or None if it is missing or unreadable."""
    try:
        with np.load(path) as data:
            return json.loads(bytes(data["episode_info"]).decode())
    except Exception:  # noqa: BLE001 - any unreadable shard is simply redone
        return None


def check_out_dir(out: Path, config, resume: bool) -> None:
    """InputError unless `out` may receive a dataset of `config` (module doc)."""
    manifest = out / MANIFEST
    if manifest.exists():
        if not resume:
            raise InputError(f"--out {out} already holds a dataset; pass --resume to continue it "
                             "or choose another --out")
        try:
            previous = json.loads(manifest.read_text())["config"]
        except (OSError, ValueError, KeyError):
            raise InputError(f"{manifest} is unreadable; delete {out} and collect again") from None
        mine = json.loads(json.dumps(config.to_dict()))
        if "human" in mine:
            previous.setdefault("human", "idm")   # datasets from before the choice were IDM/MOBIL
        if isinstance(previous.get("raster"), dict):
            previous["raster"].setdefault("predict_s", 0.0)   # from before predict_s: drew none
        for data in (previous, mine):
            data.get("family_setup", {}).pop("teacher", None)   # `human` says who drove
        if {k: v for k, v in previous.items() if k != "episodes"} != \
                {k: v for k, v in mine.items() if k != "episodes"}:
            raise InputError(f"--out {out} was collected with a different configuration; "
                             "resume with the same --env/--seed or choose another --out")
    elif holds_work(out):
        raise InputError(f"--out {out} exists and is not a dataset directory; choose another --out")


def write_index_and_manifest(out: Path, config, infos: list[dict],
                             elapsed_s: float, extra: dict | None = None) -> dict:
    """Write the index of shards and the manifest (config, provenance, counts, and `extra`)."""
    infos = sorted(infos, key=lambda i: i["episode"])
    # A shard's group (recorded data: site and configuration) lets training split by group.
    index = {"shards": [{"file": f"{SHARD_DIR}/{shard_path(out, i['episode']).name}",
                         "episode": i["episode"], "windows": i["windows"],
                         **({"group": i["group"]} if "group" in i else {})} for i in infos]}
    manifest = {
        "config": config.to_dict(),
        "seed": config.seed,
        **provenance(),
        "counts": {
            "episodes": len(infos),
            "windows": int(sum(i["windows"] for i in infos)),
            "ego_crashes": int(sum(i["ego_crashed"] for i in infos)),
            "ego_off_network": int(sum(i["ego_off_network"] for i in infos)),
            "simulated_s": float(sum(i["simulated_s"] for i in infos)),
        },
        "last_run_elapsed_s": round(elapsed_s, 3),
        **(extra or {}),
    }
    # The manifest first: it is what --resume recognises a dataset by (a run killed between the
    # two writes resumes and rewrites the index).
    write_json(out / MANIFEST, manifest)
    write_json(out / INDEX, index)
    return manifest


# --- worker processes: the source's state made once per process, reused across items ------------

_WORKER: dict = {}


def _worker_init(source: CollectSource, out: str) -> None:
    _WORKER["source"], _WORKER["out"] = source, Path(out)
    _WORKER["state"] = source.worker_state()


def _worker_item(item: int) -> dict:
    windows, info = _WORKER["source"].windows(_WORKER["state"], item)
    write_episode_shard(_WORKER["out"], windows, info)
    return info


def collect_source(source: CollectSource, out: Path, workers: int = 1, resume: bool = False,
                   progress: bool = True) -> dict:
    """Write every item of `source` not yet in `out` as a shard, then the index and the manifest;
    returns the manifest."""
    from tqdm import tqdm

    out = Path(out)
    if not (isinstance(workers, int) and workers >= 1):
        raise InputError(f"--workers must be a positive integer, got {workers!r}")
    config = source.config
    check_out_dir(out, config, resume)
    created = not out.exists()
    lock_out_dir(out)   # one writer per dataset (creates it)
    start = time.perf_counter()
    items = list(source.items())
    done = {}
    for item in items:
        info = read_episode_info(shard_path(out, item)) if resume else None
        if info is not None:
            done[item] = info
    todo = [i for i in items if i not in done]
    infos = list(done.values())
    (out / SHARD_DIR).mkdir(parents=True, exist_ok=True)
    # Write the manifest first so that an interrupted run is recognised by --resume.
    write_index_and_manifest(out, config, infos, 0.0)
    bar = tqdm(total=len(items), initial=len(done), unit=source.unit, disable=not progress,
               desc=source.label)
    try:
        for _, info in run_parallel(_worker_item, todo, workers,
                                    initializer=functools.partial(_worker_init, source, str(out))):
            infos.append(info)
            bar.update(1)
            bar.set_postfix(windows=sum(i["windows"] for i in infos))
    except BaseException:
        if created and not any((out / SHARD_DIR).iterdir()):
            shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        bar.close()
    infos.sort(key=lambda i: i["episode"])   # the source's additions see items in order
    return write_index_and_manifest(out, config, infos, time.perf_counter() - start,
                                    extra=source.manifest_extra(infos))
