"""Demonstrations from highway-env: the ego is driven by IDM + MOBIL (the "human").

Each episode: reset the env with a seed derived from (seed, episode), replace the ego by an
IDM/MOBIL vehicle with its own driver parameters (desired speed, time gap, politeness) -- at
intersections by default the `yielding` teacher, which also gives way at conflict zones by gap
acceptance (`riskmap.sim.yielding`; `--human idm` keeps plain IDM/MOBIL) -- step the
road at `record_hz`, record every vehicle, drop vehicles far from the ego (they cannot reach the
scene and they cost time), then cut training windows (history + future at `window_dt_s`) and
write them as one shard per episode, atomically. `--resume` skips the episodes already written.
"""

from __future__ import annotations

import functools
import json
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rasterize.config import FAMILY_EXTENTS, RasterConfig, family_of_env
from rasterize.errors import InputError
from rasterize.scene_io import pack_scenes
from rasterize.timebase import CONTROL_HZ, FUTURE_S, HISTORY_S, PLAN_DT_S
from riskmap.infra.atomic import write_json, write_npz
from riskmap.infra.parallel import run_parallel
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import holds_work, lock_out_dir
from riskmap.sim.episode import FAMILY_SETUPS, Episode, FamilySetup, make_env
from riskmap.sim.rollout import LoopConfig, drive_world
from riskmap.sim.yielding import DEMONSTRATORS, demonstrator

FORMAT_VERSION = 2
SHARD_DIR = "shards"
MANIFEST = "manifest.json"
INDEX = "index.json"


@dataclass(frozen=True)
class CollectConfig:
    """Everything that determines a dataset. Times in seconds, distances in metres."""

    env_id: str
    episodes: int
    seed: int = 0
    record_hz: int = CONTROL_HZ
    history_s: float = HISTORY_S
    future_s: float = FUTURE_S
    window_dt_s: float = PLAN_DT_S
    window_stride_s: float = 1.0
    crash_margin_s: float = 2.0        # drop windows whose future ends this close to an ego crash
    scene_radius_m: float = 120.0
    max_agents: int = 32
    raster: RasterConfig | None = None
    human: str | None = None           # the demonstrator's SPEC; None: the family's teacher

    def __post_init__(self) -> None:
        family = family_of_env(self.env_id)
        if self.human is None:
            object.__setattr__(self, "human", FAMILY_SETUPS[family].teacher)
        if self.human not in DEMONSTRATORS:
            raise InputError(f"--human {self.human!r} is not a demonstrator; choose one of "
                             f"{', '.join(DEMONSTRATORS)}")
        if not (isinstance(self.episodes, int) and self.episodes >= 1):
            raise InputError(f"--episodes must be a positive integer, got {self.episodes!r}")
        if self.raster is None:
            object.__setattr__(self, "raster", RasterConfig(FAMILY_EXTENTS[family]))
        stride = self.record_hz * self.window_dt_s
        if abs(stride - round(stride)) > 1e-9:
            raise InputError(f"window_dt_s={self.window_dt_s} must be a multiple of 1/record_hz")

    @property
    def family(self) -> str:
        return family_of_env(self.env_id)

    @property
    def setup(self) -> FamilySetup:
        return FAMILY_SETUPS[self.family]

    def to_dict(self) -> dict:
        data = asdict(self)
        data["family"] = self.family
        data["family_setup"] = asdict(self.setup)
        data["format_version"] = FORMAT_VERSION
        return data


def run_episode(env, config: CollectConfig, episode: int):
    """Simulate one episode with the demonstrator ego; returns (windows as Scenes, episode info)."""
    run = Episode(env, config.env_id, config.seed, episode, config.record_hz)
    drive_world(run, demonstrator(config.human), LoopConfig(round(config.setup.episode_s * config.record_hz), replan_every=1))
    recorder = run.recorder
    stride = int(round(config.window_stride_s * config.record_hz))
    first = int(round(config.history_s * config.record_hz))
    last = recorder.num_steps - 1 - int(round(config.future_s * config.record_hz))
    if run.crashed:  # a driver heading into a crash is no demonstration to learn from
        last -= int(round(config.crash_margin_s * config.record_hz))
    windows = [
        recorder.scene(step, config.history_s, config.future_s, config.window_dt_s,
                       config.scene_radius_m, config.max_agents, source=config.env_id)
        for step in range(first, last + 1, stride)
    ]
    info = {"episode": episode, "seed": run.seed, "driver": run.driver, "windows": len(windows),
            "simulated_s": run.time_s, "ego_crashed": run.crashed,
            "ego_off_network": run.off_network}
    return windows, info


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


# --- worker processes: one env per process, reused across episodes -------------------------------

_WORKER: dict = {}


def _worker_init(config: CollectConfig, out: str) -> None:
    import cv2

    cv2.setNumThreads(1)
    _WORKER["config"], _WORKER["out"] = config, Path(out)
    _WORKER["env"] = make_env(config.env_id, config.record_hz)


def _worker_episode(episode: int) -> dict:
    windows, info = run_episode(_WORKER["env"], _WORKER["config"], episode)
    write_episode_shard(_WORKER["out"], windows, info)
    return info


def _check_out_dir(out: Path, config: CollectConfig, resume: bool) -> None:
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


def write_index_and_manifest(out: Path, config: CollectConfig, infos: list[dict],
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


def collect(config: CollectConfig, out: Path, workers: int = 1, resume: bool = False,
            progress: bool = True) -> dict:
    """Collect `config.episodes` episodes into `out`; returns the manifest."""
    from tqdm import tqdm

    out = Path(out)
    if not (isinstance(workers, int) and workers >= 1):
        raise InputError(f"--workers must be a positive integer, got {workers!r}")
    _check_out_dir(out, config, resume)
    created = not out.exists()
    lock_out_dir(out)   # one writer per dataset (creates it)
    start = time.perf_counter()
    done = {}
    for episode in range(config.episodes):
        info = read_episode_info(shard_path(out, episode)) if resume else None
        if info is not None:
            done[episode] = info
    todo = [e for e in range(config.episodes) if e not in done]
    infos = list(done.values())
    (out / SHARD_DIR).mkdir(parents=True, exist_ok=True)
    # Write the manifest first so that an interrupted run is recognised by --resume.
    write_index_and_manifest(out, config, infos, 0.0)
    bar = tqdm(total=config.episodes, initial=len(done), unit="episode", disable=not progress,
               desc=f"collect {config.env_id}")
    try:
        for _, info in run_parallel(_worker_episode, todo, workers,
                                    initializer=functools.partial(_worker_init, config, str(out))):
            infos.append(info)
            bar.update(1)
            bar.set_postfix(windows=sum(i["windows"] for i in infos))
    except BaseException:
        if created and not any((out / SHARD_DIR).iterdir()):
            shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        bar.close()
    return write_index_and_manifest(out, config, infos, time.perf_counter() - start)
