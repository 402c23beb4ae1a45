"""Demonstrations from highway-env: the ego is driven by IDM + MOBIL (the "human").

Each episode: reset the env with a seed derived from (seed, episode), replace the ego by an
IDM/MOBIL vehicle with its own driver parameters (desired speed, time gap, politeness), step the
road at `record_hz`, record every vehicle, drop vehicles far from the ego (they cannot reach the
scene and they cost time), then cut training windows (history + future at `window_dt_s`) and
write them as one shard per episode, atomically. `--resume` skips the episodes already written.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from rasterize.config import FAMILY_EXTENTS, RasterConfig, family_of_env
from rasterize.errors import InputError
from rasterize.scene_io import pack_scenes
from riskmap.atomic import write_json, write_npz
from riskmap.provenance import provenance

FORMAT_VERSION = 2
SHARD_DIR = "shards"
MANIFEST = "manifest.json"
INDEX = "index.json"


@dataclass(frozen=True)
class DriverRanges:
    """Per-episode IDM/MOBIL parameters of the ego, drawn uniformly from these ranges."""

    desired_speed_mps: tuple[float, float]
    time_gap_s: tuple[float, float] = (1.0, 2.0)
    politeness: tuple[float, float] = (0.0, 0.5)


@dataclass(frozen=True)
class FamilySetup:
    """How one scenario family is simulated."""

    episode_s: float                   # simulated seconds per episode
    drivers: DriverRanges
    env_config: dict = field(default_factory=dict)
    keep_radius_m: float = 250.0       # vehicles farther from the ego are removed
    ego_destinations: tuple[str, ...] = ()   # exits the ego may be routed to (random per episode)
    spawn_every_s: float = 0.0         # >0: call the env's own traffic spawner this often


FAMILY_SETUPS: dict[str, FamilySetup] = {
    "highway": FamilySetup(40.0, DriverRanges((20.0, 32.0)), {"vehicles_count": 40}),
    "merge": FamilySetup(25.0, DriverRanges((20.0, 30.0))),
    "roundabout": FamilySetup(20.0, DriverRanges((8.0, 16.0)), {"duration": 20},
                              ego_destinations=("exr", "sxr", "nxr")),
    "intersection": FamilySetup(16.0, DriverRanges((6.0, 10.0)), {"duration": 16},
                                keep_radius_m=150.0, ego_destinations=("o1", "o2", "o3"),
                                spawn_every_s=1.0),
}


@dataclass(frozen=True)
class CollectConfig:
    """Everything that determines a dataset. Times in seconds, distances in metres."""

    env_id: str
    episodes: int
    seed: int = 0
    record_hz: int = 10
    history_s: float = 2.0
    future_s: float = 6.0
    window_dt_s: float = 0.5
    window_stride_s: float = 1.0
    crash_margin_s: float = 2.0        # drop windows whose future ends this close to an ego crash
    scene_radius_m: float = 120.0
    max_agents: int = 32
    raster: RasterConfig | None = None

    def __post_init__(self) -> None:
        family = family_of_env(self.env_id)
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


def episode_seed(seed: int, episode: int) -> int:
    """Independent, reproducible seed of one episode."""
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def _make_env(config: CollectConfig):
    import warnings

    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the envs)

    # The -v0 ids are the ones this toolkit is built and benchmarked on; silence gymnasium's
    # notice that newer versions exist.
    warnings.filterwarnings("ignore", message=".*is out of date.*", category=DeprecationWarning)

    env_config = {"simulation_frequency": config.record_hz, "policy_frequency": 1,
                  "duration": config.setup.episode_s}
    env_config.update(config.setup.env_config)
    return gym.make(config.env_id, config=env_config)


def _install_human_ego(base, rng: np.random.Generator, setup: FamilySetup) -> dict:
    """Replace the env's controlled vehicle by an IDM/MOBIL driver with sampled parameters."""
    from highway_env.vehicle.behavior import IDMVehicle

    old = base.vehicle
    ego = IDMVehicle.create_from(old)
    drivers = setup.drivers
    params = {
        "desired_speed_mps": float(rng.uniform(*drivers.desired_speed_mps)),
        "time_gap_s": float(rng.uniform(*drivers.time_gap_s)),
        "politeness": float(rng.uniform(*drivers.politeness)),
    }
    ego.target_speed = params["desired_speed_mps"]
    ego.TIME_WANTED = params["time_gap_s"]  # instance attributes shadow the class defaults
    ego.POLITENESS = params["politeness"]
    if setup.ego_destinations:
        destination = str(rng.choice(setup.ego_destinations))
        ego.plan_route_to(destination)
        params["destination"] = destination
    base.road.vehicles[base.road.vehicles.index(old)] = ego
    base.controlled_vehicles[0] = ego
    return params


def _off_network(road, vehicle, margin_m: float = 1.0) -> bool:
    """True once the vehicle is off every lane (past the end of the road, or off it sideways).

    highway-env's own `on_road` checks only the vehicle's assigned lane, which flickers at
    junctions of the roundabout; the nearest lane of the whole network does not.
    """
    lane = road.network.get_lane(road.network.get_closest_lane_index(vehicle.position,
                                                                     vehicle.heading))
    return not lane.on_lane(vehicle.position, margin=margin_m)


def run_episode(env, config: CollectConfig, episode: int):
    """Simulate one episode; returns (windows as Scenes, episode info dict)."""
    from rasterize.highway import TrafficRecorder

    base = env.unwrapped
    seed = episode_seed(config.seed, episode)
    env.reset(seed=seed)
    rng = np.random.default_rng([config.seed, episode, 1])
    setup = config.setup
    params = _install_human_ego(base, rng, setup)
    ego = base.vehicle
    dt = 1.0 / config.record_hz
    recorder = TrafficRecorder(base.road, ego, dt)
    recorder.record()
    n_steps = int(round(setup.episode_s * config.record_hz))
    per_second = config.record_hz
    crashed = off_network = False
    for step in range(1, n_steps + 1):
        base.road.act()
        base.road.step(dt)
        recorder.record()
        if ego.crashed:
            crashed = True
            break
        if step % per_second == 0:
            if _off_network(base.road, ego):
                off_network = True
                break
            base.road.vehicles = [v for v in base.road.vehicles if v is ego or
                                  np.linalg.norm(v.position - ego.position) <= setup.keep_radius_m]
            if setup.spawn_every_s and step % int(round(setup.spawn_every_s * per_second)) == 0:
                base._clear_vehicles()
                base._spawn_vehicle(spawn_probability=base.config["spawn_probability"])

    stride = int(round(config.window_stride_s * config.record_hz))
    first = int(round(config.history_s * config.record_hz))
    last = recorder.num_steps - 1 - int(round(config.future_s * config.record_hz))
    if crashed:  # a driver heading into a crash is no demonstration to learn from
        last -= int(round(config.crash_margin_s * config.record_hz))
    windows = [
        recorder.scene(step, config.history_s, config.future_s, config.window_dt_s,
                       config.scene_radius_m, config.max_agents, source=config.env_id)
        for step in range(first, last + 1, stride)
    ]
    info = {"episode": episode, "seed": seed, "driver": params, "windows": len(windows),
            "simulated_s": (recorder.num_steps - 1) * dt, "ego_crashed": crashed,
            "ego_off_network": off_network}
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
    _WORKER["env"] = _make_env(config)


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
        if {k: v for k, v in previous.items() if k != "episodes"} != \
                {k: v for k, v in mine.items() if k != "episodes"}:
            raise InputError(f"--out {out} was collected with a different configuration; "
                             "resume with the same --env/--seed or choose another --out")
    elif out.exists() and any(out.iterdir()):
        raise InputError(f"--out {out} exists and is not a dataset directory; choose another --out")


def write_index_and_manifest(out: Path, config: CollectConfig, infos: list[dict],
                             elapsed_s: float) -> dict:
    infos = sorted(infos, key=lambda i: i["episode"])
    index = {"shards": [{"file": f"{SHARD_DIR}/{shard_path(out, i['episode']).name}",
                         "episode": i["episode"], "windows": i["windows"]} for i in infos]}
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
    }
    write_json(out / INDEX, index)
    write_json(out / MANIFEST, manifest)
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
        if workers == 1 or len(todo) <= 1:
            _worker_init(config, str(out))
            results = map(_worker_episode, todo)
            pool = None
        else:
            pool = mp.get_context("fork").Pool(min(workers, len(todo)), _worker_init,
                                               (config, str(out)))
            results = pool.imap_unordered(_worker_episode, todo)
        for info in results:
            infos.append(info)
            bar.update(1)
            bar.set_postfix(windows=sum(i["windows"] for i in infos))
        if pool is not None:
            pool.close()
            pool.join()
    except BaseException:
        if created and not any((out / SHARD_DIR).iterdir()):
            shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        bar.close()
    return write_index_and_manifest(out, config, infos, time.perf_counter() - start)
