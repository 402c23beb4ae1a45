"""Attack scenes from recorded traffic: a vehicle of a CommonRoad recording is the attacked ego.

A recorded `AttackScene` has env_id `RECORDED_ENV` ("commonroad"), the recording's path and the
ego's obstacle id; `t0_s` is the attack time in recording time (seconds from the file's step 0).
`record_recorded_scene` makes its `SceneRecord`:

- log: every recorded vehicle (tracks smoothed as `riskmap collect --from-commonroad` smooths
  them, `SMOOTHING_S`) at 10 Hz from the recording's start up to t0 + horizon, in the file's
  obstacle order (log agent a = `RecordedTraffic` agent a); `log.ego_id` is the ego's agent.
- window: `window_rows` / `window_of` at t0 exactly as for simulated scenes (the ego, then the
  others within 60 m nearest first, at most 12), with the lanelets near the ego
  (`lanes_from_lanelets`) and the ego's route by the recordings' route rule
  (`RecordedTraffic.route`, `CommonRoadSceneConfig`'s defaults, as `CommonRoadWorld` shows it to
  a planner without route settings).
- family: the traffic-model family, from the file name (`recording_family`) unless given.

A scene is refused (InputError, the sweep skips it) when the ego is not recorded over the whole
window [t0 - 2 s, t0 + horizon], when its recorded centre leaves the mapped lanes in it (the
world's own lane check), or when no other vehicle is within 60 m at t0.

`adversary.crash.judge.rollout` drives such a scene in the world its source builds
(`adversary.crash.recorded_source`: the ego handed over at t0 on the recording's lanelets).
"""

from __future__ import annotations

import copy
import math
import re
from dataclasses import fields
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from adversary.crash.scenes import (
    HISTORY_S,
    RECORDED_ENV,
    WINDOW_DT_S,
    AttackScene,
    SceneRecord,
    window_of,
    window_rows,
)
from rasterize.commonroad.config import CommonRoadSceneConfig
from rasterize.commonroad.lanes import lanes_from_lanelets
from rasterize.commonroad.reader import load_scenario
from rasterize.commonroad.tracks import RecordedTraffic, SetBasedRecording
from rasterize.errors import InputError
from rasterize.frames import highway_env_from_world
from rasterize.timebase import CONTROL_HZ
from riskmap.data.collect_commonroad import CommonRoadCollectConfig
from riskmap.sim.records.metrics import centre_off_lane
from riskmap.sim.worlds.commonroad_replay import ReplayConfig, road_from_lanelets
from riskmap.sim.worlds.log_replay import HumanLog

LOG_DT_S = 1 / CONTROL_HZ      # the log's step (0.1 s: 10 Hz, the control rate)
# Tracks are smoothed as `riskmap collect --from-commonroad` smooths them (NGSIM positions jump).
SMOOTHING_S = next(f.default for f in fields(CommonRoadCollectConfig) if f.name == "smoothing_s")
# File-name prefixes of the recorded sites and their traffic-model family.
RECORDED_FAMILIES = (("USA_US101", "us101"), ("USA_Lanker", "lankershim"))
FAMILY_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
FINAL_SCENE_RADIUS_M, FINAL_SCENE_AGENTS = 120.0, 32    # TrafficRecorder.scene's defaults


def recording_family(path: str | Path, family: str | None = None) -> str:
    """The traffic-model family of a recording: `family` when given, else from its file name
    (`RECORDED_FAMILIES`); InputError for a name it cannot tell."""
    if family is not None:
        if not FAMILY_NAME.match(family):
            raise InputError(f"--family {family!r} must be a lower-case name (letters, digits, _), "
                             "e.g. us101 or lankershim")
        return family
    name = Path(path).name
    for prefix, known in RECORDED_FAMILIES:
        if name.startswith(prefix):
            return known
    listed = ", ".join(f"{prefix}* -> {known}" for prefix, known in RECORDED_FAMILIES)
    raise InputError(f"cannot tell the family of recording {name} from its name ({listed}); "
                     "pass --family NAME")


_TRAFFIC: dict[tuple[str, float], RecordedTraffic] = {}
_NETWORKS: dict[int, tuple[object, object]] = {}


def recording_traffic(path: str | Path, smoothing_s: float = SMOOTHING_S) -> RecordedTraffic:
    """This process's parsed recording of `path` (parsing takes up to a second)."""
    key = (str(Path(path).resolve()), float(smoothing_s))
    if key not in _TRAFFIC:
        _TRAFFIC[key] = RecordedTraffic(load_scenario(path), Path(path).stem, smoothing_s=smoothing_s)
    return _TRAFFIC[key]


def road_network(lanelet_network):
    """The highway-env `RoadNetwork` of a lanelet network, built once per process (building one
    takes about a second; the lanes never change)."""
    key = id(lanelet_network)
    if key not in _NETWORKS or _NETWORKS[key][0] is not lanelet_network:
        _NETWORKS[key] = (lanelet_network, road_from_lanelets(lanelet_network).network)
    return _NETWORKS[key][1]


def recorded_log(traffic: RecordedTraffic, ego: int, steps: int) -> HumanLog:
    """Every vehicle of `traffic` at 10 Hz over log steps 0 .. steps - 1 (agent `ego` the human)."""
    if abs(traffic.dt_s - LOG_DT_S) < 1e-9 and traffic.num_steps >= steps:
        states, valid = traffic.states[:, :steps].copy(), traffic.valid[:, :steps].copy()
    else:
        states, valid = traffic.resample(np.arange(len(traffic.ids)), LOG_DT_S * np.arange(steps))
    return HumanLog(states, valid, traffic.sizes.copy(), traffic.kinds.copy(), int(ego), LOG_DT_S,
                    False, False)


def log_traffic(traffic: RecordedTraffic, log: HumanLog) -> RecordedTraffic:
    """`traffic` (its scenario, ids and lights) whose tracks are `log`'s, on the log's time grid:
    a spliced log's others then replay the generated futures."""
    if len(traffic.ids) != log.states.shape[0]:
        raise InputError(f"recording {traffic.name} has {len(traffic.ids)} vehicles, the scene's log "
                         f"{log.states.shape[0]}; the file changed since: record the scenes again")
    out = copy.copy(traffic)
    out.states, out.valid, out.dt_s = log.states, log.valid, log.dt_s
    out.sizes, out.kinds = log.sizes, log.kinds
    out._lanelet_counts = {}      # from the log's tracks, computed when asked
    return out


def _ego_leaves_lanes(traffic: RecordedTraffic, log: HumanLog, steps: range) -> float | None:
    """The first time (s) among `steps` at which the ego's recorded centre is off every lane, as
    `CommonRoadWorld` checks it; None if never."""
    road = SimpleNamespace(network=road_network(traffic.scenario.lanelet_network))
    margin = ReplayConfig().off_road_margin_m
    for k in steps:
        state = log.states[log.ego_id, k]
        vehicle = SimpleNamespace(position=highway_env_from_world(state[:2]),
                                  heading=float(-np.arctan2(state[3], state[2])))
        if centre_off_lane(road, vehicle, margin):
            return k * log.dt_s
    return None


def attack_time(traffic: RecordedTraffic, agent: int, t0_after_s: float) -> float:
    """The attack time (recording s) `t0_after_s` after the vehicle's first recorded time, that
    first time rounded up to the window's 0.5 s grid."""
    first_s = traffic.span(agent)[0] * traffic.dt_s
    return math.ceil(first_s / WINDOW_DT_S - 1e-9) * WINDOW_DT_S + t0_after_s


def record_recorded_scene(scene: AttackScene, radius_m: float = 60.0, max_agents: int = 12,
                          family: str | None = None, traffic: RecordedTraffic | None = None) -> SceneRecord:
    """The SceneRecord of recorded vehicle `scene.ego_id` attacked at `scene.t0_s` (module doc);
    `traffic`: the parsed recording, if already at hand."""
    scene.check(control_hz=round(1 / LOG_DT_S))
    family = recording_family(scene.recording, family)
    traffic = traffic or recording_traffic(scene.recording)
    ego = traffic.index_of(scene.ego_id)
    where = scene.where
    first, last = (k * traffic.dt_s for k in traffic.span(ego))
    start_s, end_s = scene.t0_s - HISTORY_S, scene.t0_s + scene.horizon_s
    if first > start_s + 1e-9 or last < end_s - 1e-9:
        raise InputError(f"{where}: recorded from {first:.1f} to {last:.1f} s, the window needs "
                         f"{start_s:g}-{end_s:g} s; pick another vehicle or t0")
    t0_step = round(scene.t0_s / LOG_DT_S)
    log = recorded_log(traffic, ego, round(end_s / LOG_DT_S) + 1)
    off = _ego_leaves_lanes(traffic, log, range(round(start_s / LOG_DT_S), log.num_steps))
    if off is not None:
        raise InputError(f"{where}: the recorded vehicle leaves the mapped lanes at {off:.1f} s; "
                         "pick another vehicle")
    agent_ids = window_rows(log, t0_step, radius_m, max_agents)
    if len(agent_ids) < 2:
        raise InputError(f"{where}: no other vehicle within {radius_m:g} m at t0 = {scene.t0_s:g} s; "
                         "nothing to attack with, skip this vehicle")
    state = log.states[ego, t0_step]
    config = CommonRoadSceneConfig()
    lanes = lanes_from_lanelets(traffic.scenario.lanelet_network, state[:2], config.lane_radius_m)
    others = agent_ids[1:]
    route = log_traffic(traffic, log).route(ego, state, log.states[others, t0_step], log.sizes[others, 0],
                                            scene.t0_s, config)
    window = window_of(log, agent_ids, t0_step, scene.future_steps, lanes, route, scene.env_id)
    return SceneRecord(scene, log, window, agent_ids, family)


# ---- the sweep's candidates -----------------------------------------------------------------------

def sweep_files(files: list[Path], family: str | None) -> tuple[list[Path], str, list[dict]]:
    """The recordings a sweep takes its egos from: one file per moment of traffic (files of one
    configuration number that share vehicles, `traffic_groups`: the same moment with another
    vehicle taken out), the one with the most vehicles (the first of those in natural order);
    the family they all share; and the files left out, each with why."""
    from riskmap.data.collect_commonroad import natural_key, traffic_groups

    files = sorted(files, key=lambda p: natural_key(p.name))
    bad = [p for p in files if p.suffix.lower() != ".xml"]
    if bad:
        raise InputError(f"--commonroad {bad[0]} is not a CommonRoad .xml scenario; pass .xml files "
                         "or directories holding them")
    families = {p: recording_family(p, family) for p in files}
    if len(set(families.values())) > 1:
        listed = ", ".join(sorted(set(families.values())))
        raise InputError(f"--commonroad mixes recordings of several families ({listed}); record each "
                         "site into its own --out, or pass --family")
    traffics, dropped = {}, []
    for path in files:
        try:
            traffics[path] = recording_traffic(path)
        except SetBasedRecording:           # a folder may hold both kinds: use the _T ones
            dropped.append({"file": path.name, "why": "set-based scenario (_S-1): no recorded trajectories"})
    if not traffics:
        raise InputError(f"--commonroad: all {len(files)} file(s) are set-based (_S-1) scenarios; pass the "
                         "trajectory files (_T-1)")
    groups = traffic_groups(traffics)
    chosen: dict[str, Path] = {}
    for path, group in groups.items():
        best = chosen.get(group)
        if best is None or len(traffics[path].ids) > len(traffics[best].ids):
            chosen[group] = path
    kept = [p for p in files if p in chosen.values()]
    dropped += [{"file": p.name, "why": f"same traffic as {chosen[g].name}"}
                for p, g in groups.items() if chosen[g] != p]
    return kept, families[files[0]], dropped


def candidates(files: list[Path], t0_after_s: float) -> list[tuple[Path, int, float, str]]:
    """(file, obstacle id, attack time, why not) of every ego a sweep tries, in order: the files in
    order, their obstacles by id, each attacked `t0_after_s` after its first recorded time
    (`attack_time`); why-not is "" for a vehicle, else why it cannot be one."""
    out = []
    for path in files:
        traffic = recording_traffic(path)
        rows = [(int(i), attack_time(traffic, a, t0_after_s), "" if traffic.is_vehicle[a] else "not a vehicle")
                for a, i in enumerate(traffic.ids)]
        rows += [(int(i), math.nan, f"track rejected: {why}") for i, why in traffic.rejected.items()]
        out += [(path, *row) for row in sorted(rows)]
    return out


def sweep_scenes(files: list[Path], family: str, t0_after_s: float, start: int = 0,
                 todo: list[tuple[Path, int, float, str]] | None = None):
    """The sweep's candidates (`candidates(files, t0_after_s)`, or `todo`) from index `start` on,
    in order, each tried as an attack scene; nothing is written. Yields (index, file, obstacle id,
    attack time, SceneRecord or None, why not: "" for a scene). Scene `episode` is the candidate's
    index (scene_seed 0), as `adversary scenes --commonroad` and stress-test campaigns number them."""
    todo = candidates(files, t0_after_s) if todo is None else todo
    for index in range(start, len(todo)):
        path, ego_id, t0_s, why = todo[index]
        record = None
        if not why:
            try:
                record = record_recorded_scene(AttackScene(RECORDED_ENV, 0, index, t0_s, recording=str(path),
                                                           ego_id=ego_id), family=family)
            except InputError as error:
                why = str(error)
        yield index, path, ego_id, t0_s, record, why


__all__ = ["RECORDED_ENV", "candidates", "log_traffic", "record_recorded_scene", "recorded_log",
           "recording_family", "recording_traffic", "sweep_files", "sweep_scenes"]
