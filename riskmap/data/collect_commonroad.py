"""Demonstrations from recorded traffic: every recorded vehicle of CommonRoad files is a demonstrator.

Recordings of one site come as several files per traffic configuration (NGSIM in CommonRoad:
`USA_US101-10_1_T-1.xml`, `USA_US101-10_3_T-1.xml`, ... are the same moment of traffic, each
with another vehicle taken out as its planning problem), so the same recorded vehicle appears
in several files. Here:

- Files are read in sorted path order; tracks are smoothed (`RecordedTraffic(smoothing_s=...)`)
  and a track already seen in an earlier file (same obstacle id, length and speed profile:
  `track_fingerprint`) is skipped and counted, so every recorded vehicle is one demonstrator
  once. Tracks that are not finite or jump are left out by `RecordedTraffic` and counted.
- A demonstrator's windows (2 s history, 6 s future at 2 Hz) start at every step its record
  allows, one per second (`window_stride_s`).
- Each demonstrator is one shard ("episode") whose info names its `group`, so `riskmap train`
  holds out whole moments of traffic (`traffic_groups`): the site and configuration number of
  the file name (`recording_group`: `USA_US101-10` for `USA_US101-10_3_T-1`). Where the files of
  one configuration number hold several moments of traffic - Lankershim's number is its map
  (`USA_Lanker-2_*` are many moments on one map) - each moment is its own group, named by the
  configuration and its files' variant numbers (`USA_Lanker-2_15+23`). Files of one
  configuration number are one moment when they share a recorded vehicle (obstacle id), so a
  vehicle is never on both sides of a split within a configuration; US-101's configurations
  each stay one group.
- The raster family is the recordings' (`recorded_family`): `urban` for files tagged urban or
  intersection or with traffic lights (Lankershim), else `highway` (US-101). Scenes of urban
  recordings carry the traffic lights (`Scene.signals`) and their route rule waits at red
  lights (`rasterize.commonroad`).
- With `derive=True` (the default) the settings tuned to highway-env come from the recordings
  instead (`derive_settings`): the raster extent from how far the demonstrators drive in 6 s,
  the route rule's speed limit from the speeds driven, its acceleration as the one whose goal
  lands closest to where the humans were after 6 s; the spread of that goal error (metres,
  along and across the heading) is stored for the trainer's goal variance. All in the manifest.

A directory mixing sites is refused (extents and speeds differ; collect each site on its own).
Set-based scenarios (`_S-1`: intervals instead of trajectories) in a directory are skipped and
counted; a single one, or a directory of nothing else, is an error.
Each demonstrator is an item of `RecordingCollectSource`, written by the one collect driver
(`riskmap.data.collect_source.collect_source`): the same shard format, index and manifest as
`riskmap collect --env`; `--resume` keeps the shards already written.
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from rasterize.commonroad.config import CommonRoadSceneConfig
from rasterize.commonroad.reader import load_scenario
from rasterize.commonroad.tracks import RecordedTraffic, SetBasedRecording
from rasterize.config import FAMILY_EXTENTS, Extent, RasterConfig
from rasterize.errors import InputError
from rasterize.frames import ego_from_world, ego_pose
from rasterize.highway import RouteRule
from rasterize.timebase import FUTURE_S, HISTORY_S, PLAN_DT_S
from riskmap.data.collect_source import FORMAT_VERSION, MANIFEST, check_out_dir, collect_source

SOURCE = "commonroad"
# NGSIM in CommonRoad: <country>_<site>-<configuration>_<variant>_<T|S>-<version>
RECORDING_NAME = re.compile(r"^(?P<site>.+?)-(?P<configuration>\d+)_(?P<variant>\d+)_[TS]-\d+$")
ROUTE_ACCELS_MPS2 = tuple(np.round(np.arange(0.0, 2.01, 0.25), 2))   # candidates for derive
# Extents of the recorded families when they are not derived from the data: highway as
# highway-env's; urban as derived from the NGSIM Lankershim recordings (120 m ahead: 15% beyond
# the farthest 6 s drive, 97 m; 45 m a side: the widest turn, 38 m, plus a lane and 2 m).
RECORDED_FAMILY_EXTENTS: dict[str, Extent] = {
    "highway": FAMILY_EXTENTS["highway"],
    "urban": FAMILY_EXTENTS.get("urban", Extent(front_m=120.0, back_m=30.0, left_m=45.0, right_m=45.0)),
}


@dataclass(frozen=True)
class CommonRoadCollectConfig:
    """Everything that determines a recorded-traffic dataset. Seconds, metres, m/s.

    `files`: (file name, sha256) of every scenario, in collection order, so that `--resume`
    refuses a directory built from other recordings. `seed` is stored for the manifest only:
    nothing here is random. `raster`, `speed_limit_mps` and `route_accel_mps2` are the derived
    values when `derive` is on (filled in by `collect_commonroad` before anything is written).
    """

    files: tuple[tuple[str, str], ...]
    history_s: float = HISTORY_S
    future_s: float = FUTURE_S
    window_dt_s: float = PLAN_DT_S
    window_stride_s: float = 1.0
    scene_radius_m: float = 120.0
    max_agents: int = 32
    smoothing_s: float = 1.5           # Savitzky-Golay window on the recorded tracks (0: raw)
    speed_limit_mps: float = 29.06     # route rule's limit when a file gives none (65 mph)
    route_accel_mps2: float = 1.0      # route rule's acceleration (rasterize.highway.RouteRule)
    derive: bool = True                # extent, speed limit and route acceleration from the data
    # Raster family (extent when not derived): highway or urban; None: the recordings' own
    # (`recorded_family`, filled in by `collect_commonroad`).
    family: str | None = None
    raster: RasterConfig | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if self.family is not None and self.family not in RECORDED_FAMILY_EXTENTS:
            raise InputError(f"family {self.family!r} unknown for recordings; choose one of "
                             f"{', '.join(sorted(RECORDED_FAMILY_EXTENTS))}")
        if not self.smoothing_s >= 0:
            raise InputError(f"smoothing_s must be >= 0 seconds, got {self.smoothing_s}")
        if self.raster is None and self.family is not None:
            object.__setattr__(self, "raster", RasterConfig(RECORDED_FAMILY_EXTENTS[self.family]))
        object.__setattr__(self, "files", tuple(tuple(f) for f in self.files))

    @property
    def env_id(self) -> str:
        return SOURCE

    @property
    def scene(self) -> CommonRoadSceneConfig:
        return CommonRoadSceneConfig(self.history_s, self.future_s, self.window_dt_s,
                                     self.scene_radius_m, self.max_agents,
                                     speed_limit_mps=self.speed_limit_mps,
                                     route_rule=RouteRule(accel_mps2=self.route_accel_mps2),
                                     extent=None if self.raster is None else self.raster.extent)

    def to_dict(self) -> dict:
        data = asdict(self)
        data["files"] = [list(f) for f in self.files]
        data["env_id"] = SOURCE
        data["format_version"] = FORMAT_VERSION
        # Who demonstrated: the recorded drivers. `riskmap.data.collect_source.check_out_dir` reads a
        # manifest without this key as an IDM/MOBIL one, so it is always written.
        data["human"] = "recorded"
        return data


def scenario_files(inputs: list[str | Path], flag: str = "--from-commonroad") -> list[Path]:
    """The CommonRoad .xml files named by `inputs` (files, or directories searched recursively),
    sorted and without duplicates; `flag` names the option they came from in messages."""
    if not inputs:
        raise InputError(f"{flag} needs at least one scenario file or directory")
    found: set[Path] = set()
    for item in map(Path, inputs):
        if item.is_dir():
            found.update(p.resolve() for p in item.rglob("*.xml"))
        elif item.is_file():
            found.add(item.resolve())
        else:
            raise InputError(f"{flag} {item} does not exist; pass CommonRoad .xml files "
                             "or directories holding them")
    if not found:
        raise InputError(f"{flag} {' '.join(map(str, inputs))}: no .xml scenario files "
                         "found; pass CommonRoad .xml files or directories holding them")
    return sorted(found)


def recording_group(path: Path) -> tuple[str, str]:
    """(site, group) of a recording from its file name: `USA_US101-10_3_T-1` is site `USA_US101`,
    group `USA_US101-10` (its traffic configuration). Other names are their own site and group."""
    match = RECORDING_NAME.match(Path(path).stem)
    if not match:
        return Path(path).stem, Path(path).stem
    return match["site"], f"{match['site']}-{match['configuration']}"


def check_one_site(files: list[Path]) -> str:
    """The one site all `files` record; InputError naming the sites when they are mixed."""
    sites: dict[str, int] = {}
    for path in files:
        site = recording_group(path)[0]
        sites[site] = sites.get(site, 0) + 1
    if len(sites) > 1:
        listed = ", ".join(f"{s} ({n} files)" for s, n in sorted(sites.items()))
        raise InputError(f"--from-commonroad mixes recordings of several sites: {listed}; collect "
                         "each site into its own dataset (extents and speeds differ)")
    return next(iter(sites))


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def track_fingerprint(traffic: RecordedTraffic, agent: int) -> str:
    """What identifies a recorded track across files of one recording: obstacle id, record
    length and speed profile (positions are re-centred per file, speeds are not)."""
    first, last = traffic.span(agent)
    speeds = np.round(traffic.states[agent, first: last + 1, 4], 2)
    digest = hashlib.sha1(speeds.tobytes()).hexdigest()[:16]
    return f"{int(traffic.ids[agent])}:{last - first + 1}:{digest}"


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


@dataclass(frozen=True)
class Demonstrator:
    """One recorded vehicle to learn from (or to drive in an evaluation): its file, agent index
    in that file's traffic, the current steps of its windows and its group."""

    path: Path
    agent: int
    steps: tuple[int, ...]
    group: str


def _root(parent: dict, node):
    """The representative of `node`'s set in a union-find `parent` map."""
    while parent[node] != node:
        node = parent[node]
    return node


def traffic_groups(traffics: dict[Path, RecordedTraffic]) -> dict[Path, str]:
    """The group of every file (module doc): its configuration (`recording_group`) when all the
    files of that configuration are one moment of traffic (linked by shared obstacle ids), else
    its moment within the configuration, named `<configuration>_<variants joined by +>`."""
    by_group: dict[str, list[Path]] = {}
    for path in traffics:
        by_group.setdefault(recording_group(path)[1], []).append(path)
    out: dict[Path, str] = {}
    for group, paths in by_group.items():
        ids = {p: {int(o.obstacle_id) for o in traffics[p].scenario.dynamic_obstacles} for p in paths}
        parent = {p: p for p in paths}
        for k, a in enumerate(paths):
            for b in paths[k + 1:]:
                if ids[a] & ids[b]:
                    parent[_root(parent, a)] = _root(parent, b)
        moments: dict[Path, list[Path]] = {}
        for p in paths:
            moments.setdefault(_root(parent, p), []).append(p)
        if len(moments) == 1:
            out.update({p: group for p in paths})
            continue
        for members in moments.values():
            variants = sorted((m["variant"] if (m := RECORDING_NAME.match(p.stem)) else p.stem
                               for p in members), key=natural_key)
            out.update({p: f"{group}_{'+'.join(variants)}" for p in members})
    return out


def natural_key(name: str) -> list:
    """Sort key that orders `2` before `10` within names."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name)]


def recorded_family(traffics: dict[Path, RecordedTraffic]) -> str:
    """`urban` when a recording is tagged urban or intersection or has traffic lights, else
    `highway`."""
    for traffic in traffics.values():
        tags = {str(getattr(t, "value", t)) for t in (getattr(traffic.scenario, "tags", None) or ())}
        if tags & {"urban", "intersection"} or traffic.lights:
            return "urban"
    return "highway"


def unique_demonstrators(files: list[Path], config: CommonRoadCollectConfig,
                         progress: bool = False) -> tuple[list[Demonstrator], dict, dict]:
    """Every recorded vehicle with a window, once (the first file that holds its track), the
    parsed traffic per file and the counts of what was skipped."""
    from tqdm import tqdm

    traffics: dict[Path, RecordedTraffic] = {}
    skipped = {"duplicate_tracks": 0, "rejected_tracks": 0, "files_without_windows": 0,
               "set_based_files": 0}
    for path in tqdm(files, unit="file", disable=not progress, desc="read recordings"):
        try:
            traffic = RecordedTraffic(load_scenario(path), path.stem, smoothing_s=config.smoothing_s)
        except SetBasedRecording:
            if len(files) == 1:
                raise
            skipped["set_based_files"] += 1      # a folder may hold both kinds: use the _T ones
            continue
        traffics[path] = traffic
    groups = traffic_groups(traffics)
    seen: set[tuple[str, str]] = set()
    out: list[Demonstrator] = []
    for path, traffic in traffics.items():
        skipped["rejected_tracks"] += len(traffic.rejected)
        group = groups[path]
        found = demonstrators(traffic, config)
        skipped["files_without_windows"] += not found
        for agent, steps in found:
            key = (group, track_fingerprint(traffic, agent))
            if key in seen:
                skipped["duplicate_tracks"] += 1
                continue
            seen.add(key)
            out.append(Demonstrator(path, agent, tuple(steps), group))
    return out, traffics, skipped


def no_demonstrators_message(files: list[Path], config: CommonRoadCollectConfig, skipped: dict) -> str:
    """Why recordings gave nobody to learn from (or to drive), as one line."""
    if skipped.get("set_based_files") == len(files):
        return (f"all {len(files)} file(s) are set-based (_S-1) scenarios without recorded "
                "trajectories; pass the trajectory files (_T-1)")
    return (f"no recorded vehicle in {len(files)} file(s) has {config.history_s:g} s of history "
            f"and {config.future_s:g} s of future; use longer recordings")


def derived_extent(forward_m: np.ndarray, lateral_m: np.ndarray) -> Extent:
    """The raster extent recorded demonstrators need: 15% beyond the farthest any drove ahead
    in the future horizon (rounded up to 10 m), a fifth of that behind (for the traffic closing
    in), and a lane (3.7 m) plus 2 m beyond the widest lateral excursion a side (rounded up to
    5 m, at least 10 m)."""
    front = 10.0 * math.ceil(1.15 * float(np.max(forward_m)) / 10.0)
    back = 10.0 * math.ceil(0.2 * front / 10.0)
    side = max(10.0, 5.0 * math.ceil((float(np.max(lateral_m)) + 3.7 + 2.0) / 5.0))
    return Extent(front_m=front, back_m=back, left_m=side, right_m=side)


def _goal_error(traffic: RecordedTraffic, agent: int, step: int, scene: CommonRoadSceneConfig,
                present: np.ndarray) -> np.ndarray:
    """(along, across) metres from the route rule's goal to where the human was at the end of
    the future horizon, in the human's frame at `step`."""
    state = traffic.states[agent, step]
    others = [a for a in present if a != agent]
    route = traffic.route(agent, state, traffic.states[others, step], traffic.sizes[others, 0],
                          step * traffic.dt_s, scene)
    end = traffic.states[agent, step + round(scene.future_s / traffic.dt_s), :2]
    heading = float(np.arctan2(state[3], state[2]))
    return ego_from_world(end[None], state[:2], heading)[0] - ego_from_world(route[-1:], state[:2], heading)[0]


def window_goal_error(scene) -> np.ndarray:
    """(along, across) metres from a window's route goal to where its human was at the end of
    the future, in the human's frame now."""
    origin, heading = ego_pose(scene)
    end = ego_from_world(scene.ego_future_xy()[-1:], origin, heading)[0]
    return end - ego_from_world(scene.route_xy[-1:], origin, heading)[0]


def derive_settings(demos: list[Demonstrator], traffics: dict[Path, RecordedTraffic],
                    config: CommonRoadCollectConfig) -> tuple[CommonRoadCollectConfig, dict]:
    """`config` with the extent, route speed limit and route acceleration taken from the
    recordings (module doc), and a summary of what they were derived from."""
    future_steps = {p: round(config.future_s / t.dt_s) for p, t in traffics.items()}
    forward, lateral, speeds = [], [], []
    for demo in demos:
        traffic = traffics[demo.path]
        first, last = traffic.span(demo.agent)
        speeds.append(traffic.states[demo.agent, first: last + 1, 4])
        for step in demo.steps:
            state = traffic.states[demo.agent, step]
            future = traffic.states[demo.agent, step: step + future_steps[demo.path] + 1, :2]
            ego = ego_from_world(future, state[:2], float(np.arctan2(state[3], state[2])))
            forward.append(ego[:, 0].max())
            lateral.append(np.abs(ego[:, 1]).max())
    speeds = np.concatenate(speeds)
    limit = 0.5 * math.ceil(2.0 * float(np.percentile(speeds, 99)))
    extent = derived_extent(np.array(forward), np.array(lateral))
    base = replace(config, raster=RasterConfig(extent), speed_limit_mps=limit)
    errors = {}
    for accel in ROUTE_ACCELS_MPS2:
        scene = replace(base, route_accel_mps2=float(accel)).scene
        errors[float(accel)] = float(np.mean([
            np.linalg.norm(_goal_error(traffics[d.path], d.agent, step, scene,
                                       np.flatnonzero(traffics[d.path].valid[:, step])))
            for d in demos for step in d.steps]))
    accel = min(errors, key=errors.get)
    summary = {"windows": len(forward), "speed_p50_mps": float(np.percentile(speeds, 50)),
               "speed_p99_mps": float(np.percentile(speeds, 99)),
               "forward_6s_max_m": float(np.max(forward)), "lateral_max_m": float(np.max(lateral)),
               "route_goal_error_m_by_accel": errors}
    return replace(base, route_accel_mps2=accel), summary


@dataclass(frozen=True)
class RecordingCollectSource:
    """`riskmap collect --from-commonroad`'s items: every demonstrator (`unique_demonstrators`),
    numbered in order; their files already parsed (`traffics`), so it runs in one process."""

    config: CommonRoadCollectConfig
    demos: tuple[Demonstrator, ...]
    traffics: dict[Path, RecordedTraffic]
    skipped: dict                      # what `unique_demonstrators` left out, for the manifest
    derivation: dict | None            # `derive_settings`' summary (None when not derived)
    unit = "vehicle"
    label = "collect commonroad"

    def items(self) -> range:
        return range(len(self.demos))

    def worker_state(self) -> None:
        return None

    def windows(self, state: None, episode: int) -> tuple[list, dict]:
        demo = self.demos[episode]
        traffic = self.traffics[demo.path]
        scene_config = self.config.scene
        windows = [traffic.scene(demo.agent, step, scene_config) for step in demo.steps]
        first, last = traffic.span(demo.agent)
        errors = [window_goal_error(window).tolist() for window in windows]
        info = {"episode": episode, "file": demo.path.name, "scenario": traffic.name,
                "group": demo.group, "vehicle_id": int(traffic.ids[demo.agent]),
                "windows": len(windows), "time_steps": list(demo.steps),
                "goal_error_m": errors, "simulated_s": (last - first) * traffic.dt_s,
                "ego_crashed": False, "ego_off_network": False}
        return windows, info

    def manifest_extra(self, infos: list[dict]) -> dict:
        """The settings used (derived or not), the goal error's spread, what was skipped and the
        groups."""
        config = self.config
        errors = np.array([e for i in infos for e in i["goal_error_m"]]).reshape(-1, 2)
        derived = {"speed_limit_mps": config.speed_limit_mps, "route_accel_mps2": config.route_accel_mps2,
                   "extent": asdict(config.raster.extent),
                   "goal_error_rms_m": {"along": float(np.sqrt(np.mean(errors[:, 0] ** 2))),
                                        "across": float(np.sqrt(np.mean(errors[:, 1] ** 2)))},
                   "derived_from_data": config.derive, "derivation": self.derivation}
        return {"derived": derived, "skipped": self.skipped,
                "groups": sorted({i["group"] for i in infos})}


def collect_commonroad(inputs: list[str | Path], out: Path, resume: bool = False,
                       progress: bool = True, **settings) -> dict:
    """Cut demonstrator windows from CommonRoad recordings into dataset `out`; returns the manifest.

    `settings` override `CommonRoadCollectConfig` fields (history_s, future_s, derive, ...).
    """
    out = Path(out)
    files = scenario_files(inputs)
    check_one_site(files)
    config = CommonRoadCollectConfig(files=tuple((p.name, _sha256(p)) for p in files), **settings)
    if not (out / MANIFEST).exists():
        check_out_dir(out, config, resume)     # a wrong --out fails before the slow reading
    demos, traffics, skipped = unique_demonstrators(files, config, progress)
    if not demos:
        raise InputError(no_demonstrators_message(files, config, skipped))
    if config.family is None:
        config = replace(config, family=recorded_family(traffics))
    derivation = None
    if config.derive:
        config, derivation = derive_settings(demos, traffics, config)
    source = RecordingCollectSource(config, tuple(demos), traffics, skipped, derivation)
    return collect_source(source, out, resume=resume, progress=progress)
