"""Demonstrations from recorded traffic: every recorded vehicle of CommonRoad files is a demonstrator.

For each scenario file (in sorted path order) and each vehicle in it (in increasing obstacle id)
that has its full history and future recorded at least once, the windows it drives are cut as
for simulated data (2 s history and 6 s future at 2 Hz, one every second) and written as one
shard: one "episode" is one demonstrator, so `riskmap train`, which holds out the last episodes,
holds out whole vehicles. Same shard format, index and manifest as `riskmap collect`; `--resume`
keeps the shards already written.
"""

from __future__ import annotations

import hashlib
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from rasterize.commonroad import CommonRoadSceneConfig, RecordedTraffic, load_scenario
from rasterize.config import FAMILY_EXTENTS, RasterConfig
from rasterize.errors import InputError
from riskmap.data.collect import (
    FORMAT_VERSION,
    SHARD_DIR,
    _check_out_dir,
    read_episode_info,
    shard_path,
    write_episode_shard,
    write_index_and_manifest,
)

SOURCE = "commonroad"


@dataclass(frozen=True)
class CommonRoadCollectConfig:
    """Everything that determines a recorded-traffic dataset. Seconds, metres, m/s.

    `files`: (file name, sha256) of every scenario, in collection order, so that `--resume`
    refuses a directory built from other recordings. `seed` is stored for the manifest only:
    nothing here is random.
    """

    files: tuple[tuple[str, str], ...]
    history_s: float = 2.0
    future_s: float = 6.0
    window_dt_s: float = 0.5
    window_stride_s: float = 1.0
    scene_radius_m: float = 120.0
    max_agents: int = 32
    speed_limit_mps: float = 29.06     # route rule's limit when a file gives none (65 mph)
    family: str = "highway"            # raster extent family (recorded highway traffic)
    raster: RasterConfig | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if self.family not in FAMILY_EXTENTS:
            raise InputError(f"family {self.family!r} unknown; choose one of "
                             f"{', '.join(sorted(FAMILY_EXTENTS))}")
        if self.raster is None:
            object.__setattr__(self, "raster", RasterConfig(FAMILY_EXTENTS[self.family]))
        object.__setattr__(self, "files", tuple(tuple(f) for f in self.files))

    @property
    def env_id(self) -> str:
        return SOURCE

    @property
    def scene(self) -> CommonRoadSceneConfig:
        return CommonRoadSceneConfig(self.history_s, self.future_s, self.window_dt_s,
                                     self.scene_radius_m, self.max_agents,
                                     speed_limit_mps=self.speed_limit_mps)

    def to_dict(self) -> dict:
        data = asdict(self)
        data["files"] = [list(f) for f in self.files]
        data["env_id"] = SOURCE
        data["format_version"] = FORMAT_VERSION
        return data


def scenario_files(inputs: list[str | Path]) -> list[Path]:
    """The CommonRoad .xml files named by `inputs` (files, or directories searched recursively),
    sorted and without duplicates."""
    if not inputs:
        raise InputError("--from-commonroad needs at least one scenario file or directory")
    found: set[Path] = set()
    for item in map(Path, inputs):
        if item.is_dir():
            found.update(p.resolve() for p in item.rglob("*.xml"))
        elif item.is_file():
            found.add(item.resolve())
        else:
            raise InputError(f"--from-commonroad {item} does not exist; pass CommonRoad .xml files "
                             "or directories holding them")
    if not found:
        raise InputError(f"--from-commonroad {' '.join(map(str, inputs))}: no .xml scenario files found")
    return sorted(found)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def demonstrators(traffic: RecordedTraffic, config: CommonRoadCollectConfig) -> list[tuple[int, list[int]]]:
    """(agent index, current time steps of its windows) for every vehicle with at least one window."""
    out = []
    for agent in range(len(traffic.ids)):
        if not traffic.is_vehicle[agent]:
            continue
        steps = traffic.window_steps(agent, config.scene, config.window_stride_s)
        if steps:
            out.append((agent, steps))
    return out


def collect_commonroad(inputs: list[str | Path], out: Path, resume: bool = False,
                       progress: bool = True, **settings) -> dict:
    """Cut demonstrator windows from CommonRoad recordings into dataset `out`; returns the manifest.

    `settings` override `CommonRoadCollectConfig` fields (history_s, future_s, ...).
    """
    out = Path(out)
    files = scenario_files(inputs)
    config = CommonRoadCollectConfig(files=tuple((p.name, _sha256(p)) for p in files), **settings)
    _check_out_dir(out, config, resume)
    created = not out.exists()
    start = time.perf_counter()
    (out / SHARD_DIR).mkdir(parents=True, exist_ok=True)
    write_index_and_manifest(out, config, [], 0.0)   # lets --resume recognise an interrupted run
    infos: list[dict] = []
    try:
        _collect_files(files, config, out, resume, progress, infos)
        if not infos:
            raise InputError(f"no recorded vehicle in {len(files)} file(s) has {config.history_s:g} s "
                             f"of history and {config.future_s:g} s of future; use longer recordings")
    except BaseException:
        if created and not any((out / SHARD_DIR).iterdir()):
            shutil.rmtree(out, ignore_errors=True)
        raise
    return write_index_and_manifest(out, config, infos, time.perf_counter() - start)


def _collect_files(files: list[Path], config: CommonRoadCollectConfig, out: Path, resume: bool,
                   progress: bool, infos: list[dict]) -> None:
    """Write the shard of every demonstrator not yet written; append every shard's info to `infos`."""
    from tqdm import tqdm

    episode = 0
    bar = tqdm(files, unit="file", disable=not progress, desc="collect commonroad")
    for path in bar:
        traffic = RecordedTraffic(load_scenario(path), path.stem)
        for agent, steps in demonstrators(traffic, config):
            info = read_episode_info(shard_path(out, episode)) if resume else None
            if info is None:
                windows = [traffic.scene(agent, step, config.scene) for step in steps]
                first, last = traffic.span(agent)
                info = {"episode": episode, "file": path.name, "scenario": traffic.name,
                        "vehicle_id": int(traffic.ids[agent]), "windows": len(windows),
                        "time_steps": steps, "simulated_s": (last - first) * traffic.dt_s,
                        "ego_crashed": False, "ego_off_network": False}
                write_episode_shard(out, windows, info)
            infos.append(info)
            episode += 1
        bar.set_postfix(windows=sum(i["windows"] for i in infos))
    bar.close()
