"""Attacked scenes as CommonRoad scenarios, so that other CommonRoad tools can replay them.

One attack record of an `adversary attack` run (RUN/attacks/<scene>.json) and its scene
(`adversary.crash.scenes.load_record`) give the attacked run back: the scene's 10 Hz log with the
record's generated 2 Hz tracks spliced in exactly as the judge drove them
(`adversary.crash.judge.splice_tracks`: the adversary and every other spliced row follow their
generated futures, everyone else replays the log) and the ego's closed-loop drive
(`ego_states`). `write_commonroad` writes that as

- <scene>.xml, written by commonroad-io's own writer: time step 0 is the attack time t0 (the
  recording's t0_s), dt the log's (0.1 s);
  * the lanelet network: a recorded scene's own recording (read with commonroad-io's reader),
    traffic signs and lights included (light cycles shifted so that step 0 is t0); a highway-env
    scene's lanes (the straight lanes stored with the scene, extended along their direction over
    every exported position, bounds at centre +- width / 2, neighbours linked as adjacent in the
    same direction);
  * every other vehicle present between t0 and the end of the run as a `DynamicObstacle` whose
    `TrajectoryPrediction` is what it drove in the attacked run (position, orientation, speed,
    acceleration, yaw rate at every 0.1 s step); ids: a recorded vehicle keeps its recording's
    obstacle id, a highway-env vehicle is OBSTACLE_ID_OFFSET + its log agent;
  * the ego as the `PlanningProblem` (id: the ego's own obstacle id, by the same rule): its
    initial state is the ego's state at t0, its goal a GOAL_LENGTH_M x lane-width rectangle
    around the end point of the record's route (the route rule's goal: where the ego would be
    `RouteRule.horizon_s` = the attack horizon later, `rasterize.highway.RouteRule`), moved by
    the ego's offset from the human at t0, reachable from step 0 to the end of the horizon;
  * the scenario's tags: the recording's (highway-env: highway, multi-lane, parallel lanes) plus
    "critical".
- <scene>.json beside it (the sidecar): which obstacle is the adversary (and which others were
  spliced with generated futures), the ego's driven trajectory from t0 with its box (the
  planning problem's solution as driven, for collision checks), the record's collision (time step
  in the exported time base, IoU, type, failure class) and the first collision step recomputed
  from the exported trajectories, the source files and what was left out.

Obstacles and the ego are boxes about their centre (the toolkit's convention); collisions are
the judge's box IoU > COLLISION_IOU (`collision_step`).
"""

from __future__ import annotations

import copy
import io
import json
import logging
import math
import tempfile
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

# highway-env scenes: lanelet id = LANELET_ID_OFFSET + lane index, straight lanes extended by
# LANE_EXTENSION_M (`rasterize.commonroad.lanelets`, the one builder)
from rasterize.commonroad.lanelets import LANE_EXTENSION_M, LANELET_ID_OFFSET
from rasterize.errors import InputError
from rasterize.tracks import ReadsTracks, Tracks

FORMATS = ("commonroad",)
DECIMALS = 8                    # decimal places written (commonroad-io's writer truncates there)
OBSTACLE_ID_OFFSET = 1000       # highway-env scenes: obstacle id = this + log agent
GOAL_LENGTH_M = 10.0            # the goal rectangle along the route
AUTHOR = "riskmap toolkit (adversary export)"
SIDECAR_VERSION = 1
TRAJECTORY_COLUMNS = ("time_step", "x", "y", "orientation", "velocity", "yaw_rate")


# ---- the attacked run --------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class AttackedRun(ReadsTracks):
    """The attacked run of one record, on the log's steps 0 .. last_step (module docstring).

    tracks: every log agent, the ego (`ego`) as it drove, the spliced rows as generated (`states`,
    `valid`, `sizes`, `kinds` read its arrays: `ReadsTracks`); adversary: the adversary's log agent; spliced: the
    log agents that follow generated tracks; t0_step: the log step of the attack time."""

    name: str
    attack: dict
    record: object              # adversary.crash.scenes.SceneRecord
    tracks: Tracks
    ego: int
    adversary: int
    spliced: tuple[int, ...]
    t0_step: int
    dt_s: float

    @property
    def last_step(self) -> int:
        return self.tracks.num_steps - 1

    @property
    def horizon_steps(self) -> int:
        return round(self.record.scene.horizon_s / self.dt_s)


def attacked_run(attack: dict, record, name: str = "") -> AttackedRun:
    """The attacked run of attack record `attack` (an RUN/attacks/<scene>.json) on its scene
    `record` (module docstring); InputError if the record holds no attack or does not fit."""
    from adversary.crash.judge import splice_tracks

    name = name or attack.get("name", "")
    if attack.get("status") != "ok":
        raise InputError(f"attack {name} has status {attack.get('status')!r}: no attacked run to export")
    try:
        tracks = np.asarray(attack["tracks"], dtype=np.float64).reshape(-1, record.scene.future_steps, 6)
        rows = [int(r) for r in attack["metrics"]["spliced_rows"]]
        ego_states = np.asarray(attack["ego_states"], dtype=np.float64).reshape(-1, 6)
        adversary_row = int(attack["adversary_row"])
    except (KeyError, TypeError, ValueError) as err:
        raise InputError(f"attack record {name} lacks its tracks or ego states ({err}); it was not "
                         "written by `adversary attack`") from None
    mine = asdict(record.scene)
    if any(mine.get(k, v) != v for k, v in dict(attack.get("scene") or {}).items()):
        raise InputError(f"attack record {name} was made on another scene than {record.scene.where}; "
                         "pass the run's own --scenes")
    log = splice_tracks(record, tracks, rows)
    ego, k0 = log.ego_id, record.t0_step
    first = int(np.argmax(log.valid[ego]))
    last = first + len(ego_states) - 1
    if not log.valid[ego].any() or last < k0 or last >= log.num_steps:
        raise InputError(f"attack record {name}: the ego's {len(ego_states)} states do not fit the scene's "
                         f"log of {log.num_steps} steps; pass the run's own --scenes")
    states, valid = log.states[:, :last + 1].copy(), log.valid[:, :last + 1].copy()
    states[ego, first:], valid[ego, first:] = ego_states, True
    adversary = int(record.agent_ids[adversary_row])
    if "adversary_log_id" in attack and int(attack["adversary_log_id"]) != adversary:
        raise InputError(f"attack record {name} names log agent {attack['adversary_log_id']} as the "
                         f"adversary, its scene row {adversary_row} is agent {adversary}; pass the run's "
                         "own --scenes")
    spliced = tuple(int(record.agent_ids[r]) for r in rows)
    return AttackedRun(name, attack, record, Tracks(states, valid, log.sizes.copy(), log.kinds.copy()), ego,
                       adversary, spliced, k0, float(log.dt_s))


def collision_step(tracks: Tracks, ego: int, other: int, from_step: int = 0) -> tuple[int | None, float]:
    """(first step >= from_step at which the boxes of `ego` and `other` overlap with IoU >
    COLLISION_IOU, that IoU); (None, largest IoU seen) if never: the judge's criterion
    (`adversary.crash.judge.first_collision`)."""
    from adversary.crash.judge import first_collision

    step, _, iou = first_collision(tracks, ego, [other], from_step)
    return step, iou


# ---- CommonRoad objects ------------------------------------------------------------------------

def _orientation(heading_xy: np.ndarray) -> np.ndarray:
    return np.arctan2(heading_xy[..., 1], heading_xy[..., 0])


def _accelerations(speeds: np.ndarray, dt_s: float) -> np.ndarray:
    """Backward differences of the speeds (0 at the first), as the recorder computes yaw rates."""
    return np.concatenate([[0.0], np.diff(speeds) / dt_s]) if len(speeds) else speeds


def _states(track: np.ndarray, steps: np.ndarray, dt_s: float, initial: bool = False,
            speed_before: float | None = None) -> list:
    """CommonRoad states of toolkit states `track` [T, 6] at time steps `steps` [T];
    `speed_before`: the speed one step before the first (its acceleration; else 0)."""
    from rasterize.commonroad_compat import CustomState, InitialState

    speeds = track[:, 4] if speed_before is None else np.concatenate([[speed_before], track[:, 4]])
    accel = _accelerations(speeds, dt_s)[0 if speed_before is None else 1:]
    out = []
    for state, step, a in zip(track, steps, accel):
        values = dict(time_step=int(step), position=np.array(state[:2], dtype=np.float64),
                      orientation=float(_orientation(state[2:4])), velocity=float(state[4]),
                      acceleration=float(a), yaw_rate=float(state[5]))
        out.append(InitialState(**values, slip_angle=0.0) if initial else CustomState(**values))
    return out


def _first_segment(valid: np.ndarray, start: int) -> tuple[int, int] | None:
    """(first, last) log steps of the first run of valid steps at or after `start`; None if none."""
    present = np.flatnonzero(valid[start:])
    if not present.size:
        return None
    first = start + int(present[0])
    gaps = np.flatnonzero(~valid[first:])
    last = first + int(gaps[0]) - 1 if gaps.size else len(valid) - 1
    return first, last


def _dynamic_obstacle(run: AttackedRun, agent: int, obstacle_id: int, obstacle_type) -> tuple:
    """(DynamicObstacle of `agent` from t0 to the end of the run, or None if absent, and the
    number of its valid steps left out: those after a gap in its record)."""
    from rasterize.commonroad_compat import DynamicObstacle, Trajectory, TrajectoryPrediction, rect_shape

    span = _first_segment(run.valid[agent], run.t0_step)
    if span is None or span[0] == span[1]:
        # absent after t0, or there for one step only (CommonRoad's schema wants a trajectory)
        return None, 0 if span is None else 1
    first, last = span
    left_out = int(run.valid[agent, last + 1:].sum())
    steps = np.arange(first, last + 1)
    before = float(run.states[agent, first - 1, 4]) if first > 0 and run.valid[agent, first - 1] else None
    states = _states(run.states[agent, first:last + 1], steps - run.t0_step, run.dt_s, speed_before=before)
    initial = _states(run.states[agent, first:first + 1], steps[:1] - run.t0_step, run.dt_s, initial=True,
                      speed_before=before)[0]
    shape = rect_shape(length=float(run.sizes[agent, 0]), width=float(run.sizes[agent, 1]))
    prediction = TrajectoryPrediction(Trajectory(int(steps[1] - run.t0_step), states[1:]), shape)
    return DynamicObstacle(int(obstacle_id), obstacle_type, shape, initial, prediction), left_out


def _goal(run: AttackedRun, lane_width_m: float) -> tuple:
    """(GoalRegion, its description for the sidecar): module docstring."""
    from rasterize.commonroad_compat import CustomState, GoalRegion, Interval, rect_region

    ego_t0 = run.states[run.ego, run.t0_step]
    route = run.record.window.route_xy
    if route is None or len(route) == 0:
        # no route in the record: straight on at the ego's speed
        end = ego_t0[:2] + ego_t0[2:4] * ego_t0[4] * run.record.scene.horizon_s
        direction, rule = ego_t0[2:4], "straight ahead at the speed at t0 (the record has no route)"
    else:
        end = route[-1] + (ego_t0[:2] - route[0])
        steps = np.diff(route, axis=0)
        moving = steps[np.linalg.norm(steps, axis=1) > 1e-6] if len(steps) else steps
        direction = moving[-1] if len(moving) else ego_t0[2:4]
        rule = ("end of the record's route (the route rule's goal after its horizon), moved by the ego's "
                "offset from the route's start at t0")
    orientation = float(np.arctan2(direction[1], direction[0]))
    rect = rect_region(end, length=GOAL_LENGTH_M, width=float(lane_width_m), orientation=orientation)
    steps = (0, run.horizon_steps)
    region = GoalRegion([CustomState(time_step=Interval(*steps), position=rect)])
    return region, {"center": [float(end[0]), float(end[1])], "orientation": orientation,
                    "length_m": GOAL_LENGTH_M, "width_m": float(lane_width_m), "time_steps": list(steps),
                    "rule": rule}


def _lane_width(record) -> float:
    lanes = record.window.lanes
    return float(np.median([lane.width_m for lane in lanes])) if lanes else 4.0


def _planning_problem(run: AttackedRun, problem_id: int) -> tuple:
    from rasterize.commonroad_compat import PlanningProblem, PlanningProblemSet

    k0, ego = run.t0_step, run.ego
    before = float(run.states[ego, k0 - 1, 4]) if k0 > 0 and run.valid[ego, k0 - 1] else None
    initial = _states(run.states[ego, k0:k0 + 1], np.array([0]), run.dt_s, initial=True,
                      speed_before=before)[0]
    goal, described = _goal(run, _lane_width(run.record))
    return PlanningProblemSet([PlanningProblem(int(problem_id), initial, goal)]), described


# ---- the road: a recording's lanelets, or highway-env's straight lanes ----------------------------

def _read_recording(path: str):
    """(Scenario, PlanningProblemSet) of a CommonRoad recording, read by commonroad-io.

    Its XML reader, which is what `CommonRoadFileReader` runs for .xml files: importing
    `CommonRoadFileReader` also imports its protobuf reader, which needs an older protobuf
    runtime than the one installed here (see `rasterize.commonroad_compat`)."""
    from rasterize.commonroad_compat import XMLFileReader

    if not Path(path).is_file():
        raise InputError(f"recording {path} is not there; put it back (the scenes were cut from it)")
    logging.getLogger(XMLFileReader.__module__).setLevel(logging.ERROR)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return XMLFileReader(str(path)).open()


def _shift_lights(network, steps: int) -> None:
    """Traffic-light cycles shifted so that time step 0 is the recording's step `steps`."""
    for light in network.traffic_lights:
        cycle = light.traffic_light_cycle
        if cycle is None or not cycle.cycle_elements:
            continue
        total = sum(int(e.duration) for e in cycle.cycle_elements)
        cycle.time_offset = int((cycle.time_offset - steps) % total) if total > 0 else cycle.time_offset


def _recorded_scenario(run: AttackedRun) -> tuple:
    """(Scenario, id of each log agent, tags, source facts) of a recorded scene."""
    from adversary.crash.recorded import recording_traffic
    from rasterize.commonroad_compat import Scenario, Tag

    scene = run.record.scene
    original, _ = _read_recording(scene.recording)
    traffic = recording_traffic(scene.recording)
    if len(traffic.ids) != len(run.sizes) or traffic.index_of(scene.ego_id) != run.ego:
        raise InputError(f"{scene.recording} no longer matches scene {scene.where}; record the scenes again")
    network = copy.deepcopy(original.lanelet_network)
    if network.traffic_lights:
        if abs(float(original.dt) - run.dt_s) > 1e-9:
            raise InputError(f"{scene.recording} has traffic lights on a {original.dt} s grid, the attack's "
                             f"log a {run.dt_s} s one; exporting such recordings is not supported")
        _shift_lights(network, run.t0_step)
    scenario_id = copy.deepcopy(original.scenario_id)
    scenario_id.prediction_id = int(scene.episode) + 1          # one benchmark id per scene
    tags = (set(original.tags or ()) - {Tag.COMFORT}) | {Tag.CRITICAL}    # attacked: no comfort scene
    scenario = Scenario(run.dt_s, scenario_id, tags=tags)
    scenario.add_objects(network)
    for obstacle in original.static_obstacles:               # never in the log; they do not move
        scenario.add_objects(copy.deepcopy(obstacle))
    types = {int(o.obstacle_id): o.obstacle_type for o in original.dynamic_obstacles}
    ids = [int(i) for i in traffic.ids]
    source = {"recording": str(scene.recording), "recording_obstacle_ids": "kept",
              "recording_dt_s": float(original.dt), "t0_recording_s": float(scene.t0_s),
              "left_out": [{"obstacle_id": int(i), "why": f"not in the attack's log: {why}"}
                           for i, why in sorted(traffic.rejected.items())]}
    return scenario, ids, [types[i] for i in ids], tags, source


def _highway_lanelets(run: AttackedRun) -> list:
    """Lanelets of a highway-env scene's stored lanes over every exported position (module
    docstring): the one builder, `rasterize.commonroad.lanelets`, which the CommonRoad planner
    adapter shares."""
    from rasterize.commonroad.lanelets import lanelets_from_lanes

    lanes = run.record.window.lanes
    if not lanes:
        raise InputError(f"scene {run.record.scene.where} holds no lanes; nothing to build a road from")
    xy = run.states[:, run.t0_step:, :2][run.valid[:, run.t0_step:]]
    return lanelets_from_lanes(lanes, xy, LANE_EXTENSION_M, LANELET_ID_OFFSET)


def _highway_scenario(run: AttackedRun) -> tuple:
    from rasterize.commonroad_compat import ObstacleType, Scenario, ScenarioID, Tag
    from rasterize.scene import AgentKind

    scene = run.record.scene
    scenario_id = ScenarioID(country_id="ZAM", map_name="HighwayEnv", map_id=1,
                             configuration_id=int(scene.scene_seed) + 1, obstacle_behavior="T",
                             prediction_id=int(scene.episode) + 1)
    tags = {Tag.HIGHWAY, Tag.MULTI_LANE, Tag.PARALLEL_LANES, Tag.NO_ONCOMING_TRAFFIC, Tag.SIMULATED,
            Tag.CRITICAL}
    scenario = Scenario(run.dt_s, scenario_id, tags=tags)
    for lanelet in _highway_lanelets(run):
        scenario.add_objects(lanelet)
    ids = [OBSTACLE_ID_OFFSET + a for a in range(len(run.sizes))]
    types = [ObstacleType.CAR if int(k) == int(AgentKind.VEHICLE) else ObstacleType.UNKNOWN
             for k in run.kinds]
    source = {"env_id": scene.env_id, "scene_seed": int(scene.scene_seed), "episode": int(scene.episode),
              "static_agents": int(scene.static_agents), "obstacle_ids": f"{OBSTACLE_ID_OFFSET} + log agent",
              "lanes": "the scene's stored lanes; straight ones extended along their direction",
              "left_out": []}
    return scenario, ids, types, tags, source


# ---- writing -----------------------------------------------------------------------------------

def build_commonroad(run: AttackedRun) -> tuple:
    """(Scenario, PlanningProblemSet, tags, sidecar dict) of an attacked run (module docstring)."""
    scene = run.record.scene
    scenario, ids, types, tags, source = (_recorded_scenario(run) if scene.recording
                                          else _highway_scenario(run))
    obstacles, truncated = {}, {}
    for agent in range(len(run.sizes)):
        if agent == run.ego:
            continue
        obstacle, left_out = _dynamic_obstacle(run, agent, ids[agent], types[agent])
        if obstacle is None:
            if left_out:
                source["left_out"].append({"obstacle_id": ids[agent], "why": "on the road for one time step "
                                           "of the run only: no trajectory to write"})
            continue
        scenario.add_objects(obstacle)
        obstacles[agent] = obstacle
        if left_out:
            truncated[ids[agent]] = left_out
    if run.adversary not in obstacles:
        raise InputError(f"attack {run.name}: the adversary is not on the road after t0; nothing to export")
    problems, goal = _planning_problem(run, ids[run.ego])
    k0 = run.t0_step
    ego_steps = np.flatnonzero(run.valid[run.ego, k0:]) + k0
    ego_track = run.states[run.ego, ego_steps]
    metrics = run.attack.get("metrics") or {}
    record_step = (None if metrics.get("collision_time_s") is None
                   else round(metrics["collision_time_s"] / run.dt_s) - k0)
    recomputed, iou = collision_step(run.tracks, run.ego, run.adversary, k0)
    rows = {int(a): r for r, a in enumerate(run.record.agent_ids)}
    sidecar = {
        "version": SIDECAR_VERSION, "format": "commonroad", "scene": run.name,
        "scenario_id": str(scenario.scenario_id), "dt_s": run.dt_s,
        "time_step_0": {"log_step": k0, "time_s": round(k0 * run.dt_s, 9),
                        "note": "time step 0 is the attack time t0 (log step t0_step)"},
        "horizon_steps": run.horizon_steps, "end_time_step": run.last_step - k0,
        "planner": run.attack.get("planner"), "selector": run.attack.get("selector"),
        "adversary": {"obstacle_id": ids[run.adversary], "log_agent": run.adversary,
                      "window_row": int(run.attack["adversary_row"]),
                      "trajectory": "generated: the record's 2 Hz tracks spliced in at 10 Hz as the "
                                    "judge drove them"},
        "spliced_obstacle_ids": sorted(ids[a] for a in run.spliced if a in obstacles),
        "obstacles": [{"obstacle_id": ids[a], "log_agent": a, "window_row": rows.get(a),
                       "spliced": a in run.spliced, "adversary": a == run.adversary}
                      for a in sorted(obstacles)],
        "truncated_obstacles": {str(k): v for k, v in truncated.items()},
        "planning_problem_id": ids[run.ego],
        "ego": {"log_agent": run.ego, "length_m": float(run.sizes[run.ego, 0]),
                "width_m": float(run.sizes[run.ego, 1]),
                "recording_obstacle_id": int(scene.ego_id) if scene.recording else None,
                "trajectory_columns": list(TRAJECTORY_COLUMNS),
                "trajectory": [[int(k - k0), *(float(v) for v in s[:2]), float(_orientation(s[2:4])),
                                float(s[4]), float(s[5])] for k, s in zip(ego_steps, ego_track)]},
        "goal": goal,
        "collision": {"with_adversary": bool(run.attack.get("collision")), "time_step": record_step,
                      "time_s": metrics.get("collision_time_s"), "iou": metrics.get("collision_iou"),
                      "type": metrics.get("collision_type"), "failure": metrics.get("failure"),
                      "recomputed_time_step": None if recomputed is None else recomputed - k0,
                      "recomputed_iou": iou,
                      "criterion": "box IoU > 0.02 between the ego's and the adversary's boxes "
                                   "(the judge's)"},
        "source": {**source, "attack_scene": dict(run.attack.get("scene") or {})},
        "tags": sorted(t.value for t in tags),
    }
    return scenario, problems, tags, sidecar


def write_commonroad(attack: dict, record, out_dir: Path, name: str = "",
                     origin: dict | None = None) -> tuple[Path, Path]:
    """Write attack record `attack` on scene `record` as OUT_DIR/<name>.xml and its sidecar
    OUT_DIR/<name>.json (module docstring); returns both paths. The sidecar is written last.
    `origin`: where the attack comes from when not an `adversary attack` run (a campaign job:
    {"campaign": DIR, "job_id": ID}), added to the sidecar's source and named in the XML's."""
    from rasterize.commonroad_compat import OverwriteExistingFile, XMLFileWriter
    from riskmap.infra.atomic import atomic_write, write_json

    name = name or attack.get("name") or "scene"
    run = attacked_run(attack, record, name)
    scenario, problems, tags, sidecar = build_commonroad(run)
    out_dir = Path(out_dir)
    xml, side = out_dir / f"{name}.xml", out_dir / f"{name}.json"
    made_by = ("adversary attack" if not origin else
               f"adversary stress-test {origin.get('campaign')} job {origin.get('job_id')}")
    source = f"{made_by} ({attack.get('planner')}, {attack.get('selector')}) on {record.scene.where}"
    if origin:
        sidecar = {**sidecar, "source": {**sidecar["source"], **origin}}
    writer = XMLFileWriter(scenario, problems, AUTHOR, "", source, tags, decimal_precision=DECIMALS)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / xml.name
        writer.write_to_file(str(path), OverwriteExistingFile.ALWAYS)
        data = path.read_bytes()
    atomic_write(xml, lambda f: f.write(data))
    write_json(side, {**sidecar, "xml": xml.name})
    return xml, side


# ---- reading back --------------------------------------------------------------------------------

def read_exported(xml: Path) -> tuple:
    """(Scenario, PlanningProblemSet, sidecar) of an exported scene (`<scene>.xml` and its
    `<scene>.json`), read with commonroad-io's reader."""
    sidecar = json.loads(Path(xml).with_suffix(".json").read_text())
    scenario, problems = _read_recording(str(xml))
    return scenario, problems, sidecar


def obstacle_track(obstacle, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(states [T, 6] in the toolkit's convention, valid [T]) of a CommonRoad dynamic obstacle at
    time `steps`."""
    states, valid = np.zeros((len(steps), 6)), np.zeros(len(steps), dtype=bool)
    for i, k in enumerate(steps):
        state = obstacle.state_at_time(int(k))
        if state is None:
            continue
        theta = float(state.orientation)
        states[i] = [*np.asarray(state.position, dtype=np.float64), math.cos(theta), math.sin(theta),
                     float(state.velocity), float(getattr(state, "yaw_rate", 0.0) or 0.0)]
        valid[i] = True
    return states, valid


def ego_track(sidecar: dict, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(states [T, 6], valid [T]) of the ego's driven trajectory in a sidecar at time `steps`."""
    rows = {int(r[0]): r for r in sidecar["ego"]["trajectory"]}
    states, valid = np.zeros((len(steps), 6)), np.zeros(len(steps), dtype=bool)
    for i, k in enumerate(steps):
        if int(k) in rows:
            _, x, y, theta, v, w = rows[int(k)]
            states[i], valid[i] = [x, y, math.cos(theta), math.sin(theta), v, w], True
    return states, valid


def exported_collision_step(xml: Path) -> int | None:
    """The first time step at which the exported ego and adversary boxes overlap (the judge's
    IoU criterion), from the exported files alone."""
    scenario, _, sidecar = read_exported(xml)
    steps = np.arange(0, sidecar["end_time_step"] + 1)
    adversary = scenario.obstacle_by_id(sidecar["adversary"]["obstacle_id"])
    adv, adv_valid = obstacle_track(adversary, steps)
    ego, ego_valid = ego_track(sidecar, steps)
    sizes = np.array([[sidecar["ego"]["length_m"], sidecar["ego"]["width_m"]],
                      [adversary.obstacle_shape.length, adversary.obstacle_shape.width]])
    kinds = np.zeros(2, dtype=np.int8)        # AgentKind.VEHICLE: the kinds do not count here
    step, _ = collision_step(Tracks(np.stack([ego, adv]), np.stack([ego_valid, adv_valid]), sizes, kinds), 0, 1)
    return step


# ---- a picture -----------------------------------------------------------------------------------


def add_exported(entry: dict, name: str, out: Path, index: dict, plot: bool, resume: bool) -> None:
    """One exported scene into the export's index, drawn first with `--plot` (kept on `--resume`);
    attack runs and campaigns alike."""
    if plot:
        entry["png"] = f"{name}.png"
        if not (resume and (out / f"{name}.png").is_file()):
            render_png(out / f"{name}.xml", out / f"{name}.png")
    index["exported"].append(entry)


def render_png(xml: Path, png: Path, time_step: int | None = None, radius_m: float = 60.0) -> int:
    """Draw an exported scene with commonroad-io's MPRenderer at `time_step` (default: the
    record's collision step, else 0): the lanelets, every obstacle (the adversary red), the ego's
    driven box (green) and its goal region; returns the step drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from rasterize.commonroad_compat import (
        DynamicObstacle,
        ObstacleType,
        Trajectory,
        TrajectoryPrediction,
        mp_renderer,
        rect_shape,
    )
    from riskmap.infra.atomic import atomic_write

    MPRenderer, MPDrawParams = mp_renderer()

    scenario, problems, sidecar = read_exported(xml)
    if time_step is None:
        time_step = sidecar["collision"]["time_step"]
        time_step = 0 if time_step is None else int(time_step)
    ego_steps = np.array([r[0] for r in sidecar["ego"]["trajectory"]])
    ego, _ = ego_track(sidecar, ego_steps)
    if not 0 <= time_step <= sidecar["end_time_step"]:
        raise InputError(f"time step {time_step} is outside {xml} (0..{sidecar['end_time_step']})")
    at = min(int(np.searchsorted(ego_steps, time_step)), len(ego_steps) - 1)
    shape = rect_shape(length=sidecar["ego"]["length_m"], width=sidecar["ego"]["width_m"])
    states = _states(ego, ego_steps, sidecar["dt_s"])
    initial = _states(ego[:1], ego_steps[:1], sidecar["dt_s"], initial=True)[0]
    ego_obstacle = DynamicObstacle(sidecar["planning_problem_id"], ObstacleType.CAR, shape, initial,
                                   TrajectoryPrediction(Trajectory(int(ego_steps[1]), states[1:]), shape)
                                   if len(states) > 1 else None)
    centre = ego[at, :2]
    fig, ax = plt.subplots(figsize=(14, 6))
    rnd = MPRenderer(ax=ax, plot_limits=[centre[0] - radius_m, centre[0] + radius_m,
                                         centre[1] - 0.45 * radius_m, centre[1] + 0.45 * radius_m])
    params = MPDrawParams()
    params.time_begin = time_step
    params.dynamic_obstacle.draw_icon = False
    params.dynamic_obstacle.show_label = True
    params.dynamic_obstacle.trajectory.draw_trajectory = False
    params.lanelet_network.lanelet.draw_start_and_direction = False
    scenario.lanelet_network.draw(rnd, params)
    adversary_id = sidecar["adversary"]["obstacle_id"]
    for obstacle in scenario.dynamic_obstacles:
        p = copy.deepcopy(params)
        if obstacle.obstacle_id == adversary_id:
            p.dynamic_obstacle.vehicle_shape.occupancy.shape.facecolor = "#d62728"
            p.dynamic_obstacle.vehicle_shape.occupancy.shape.edgecolor = "#7f0000"
            p.dynamic_obstacle.trajectory.draw_trajectory = True
            p.dynamic_obstacle.trajectory.facecolor = "#d62728"
            p.dynamic_obstacle.time_end = time_step
        obstacle.draw(rnd, p.dynamic_obstacle)
    p = copy.deepcopy(params)
    p.dynamic_obstacle.vehicle_shape.occupancy.shape.facecolor = "#2ca02c"
    p.dynamic_obstacle.vehicle_shape.occupancy.shape.edgecolor = "#0b4d0b"
    p.dynamic_obstacle.zorder = 30
    ego_obstacle.draw(rnd, p.dynamic_obstacle)
    for problem in problems.planning_problem_dict.values():
        problem.goal.draw(rnd, params.goal_region)
    rnd.render()
    # the whole run's paths over the picture (matplotlib, after commonroad-io has drawn)
    adversary = scenario.obstacle_by_id(adversary_id)
    adv, adv_valid = obstacle_track(adversary, np.arange(0, sidecar["end_time_step"] + 1))
    ax.plot(adv[adv_valid, 0], adv[adv_valid, 1], "--", color="#d62728", lw=1.2, zorder=40,
            label="adversary, generated (t0 to end)")
    ax.plot(ego[:, 0], ego[:, 1], "--", color="#2ca02c", lw=1.2, zorder=40, label="ego, driven (t0 to end)")
    ax.legend(loc="lower left", fontsize=8)
    collision = sidecar["collision"]
    from riskmap.registry import display_name

    title = (f"{sidecar['scene']} ({sidecar['scenario_id']}) | {display_name(sidecar['planner'])} / "
             f"{sidecar['selector']} | "
             f"t = {time_step * sidecar['dt_s']:.1f} s after t0 | ego green (planning problem "
             f"{sidecar['planning_problem_id']}), adversary red ({adversary_id})")
    if collision["time_step"] is not None:
        title += f"\ncollision at step {collision['time_step']}: {collision['type']}"
        if collision.get("failure"):
            f = collision["failure"]
            title += f", {f.get('fault')}, avoidable={f.get('avoidable')}, counts={f.get('counts')}"
    ax.set_title(title, fontsize=9)
    png = Path(png)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120, bbox_inches="tight")
    plt.close(fig)
    atomic_write(png, lambda f: f.write(buffer.getvalue()))
    return time_step


# ---- a whole run ---------------------------------------------------------------------------------

def export_target(fmt: str, out: Path) -> Path:
    """What every `adversary export` checks before reading anything: `fmt` is a known format and
    `out` is not a file (InputError naming the fix otherwise). Returns `out` as a Path."""
    if fmt not in FORMATS:
        raise InputError(f"--format {fmt!r} is unknown; use one of {', '.join(FORMATS)}")
    out = Path(out)
    if out.is_file():
        raise InputError(f"--out {out} is a file; pass a folder for the exported scenes")
    return out


def read_attack_run(run_dir: Path) -> dict:
    """run.json of an `adversary attack` run folder (InputError naming the fix otherwise)."""
    run_dir = Path(run_dir)
    fix = "pass the --out folder of an `adversary attack` run (it holds run.json and attacks/)"
    if not run_dir.is_dir():
        raise InputError(f"--run {run_dir} is not a folder; {fix}")
    try:
        meta = json.loads((run_dir / "run.json").read_text())
    except (OSError, ValueError):
        raise InputError(f"--run {run_dir} holds no readable run.json, so it is not an attack run; "
                         f"{fix}") from None
    if not isinstance(meta, dict) or "scenes" not in meta or "planner" not in meta \
            or not (run_dir / "attacks").is_dir():
        raise InputError(f"--run {run_dir} is not an attack run (its run.json names no scenes, or it has no "
                         f"attacks/); {fix}")
    return meta


def scenes_of(run_dir: Path, meta: dict, scenes: Path | None = None) -> Path:
    """The scene folder of an attack run: `scenes` if given, else the one its run.json names."""
    path = Path(scenes) if scenes is not None else Path(meta["scenes"])
    if not (path / "index.json").is_file():
        said = "--scenes" if scenes is not None else f"the run's run.json ({run_dir}/run.json)"
        raise InputError(f"scene folder {path} named by {said} holds no index.json; pass the attack's scene "
                         "folder with --scenes DIR")
    return path


def export_run(run_dir: Path, out: Path, fmt: str = "commonroad", only_failures: bool = False,
               resume: bool = False, scenes: Path | None = None, names: tuple[str, ...] = (),
               plot: bool = False, progress: bool = True) -> dict:
    """`adversary export`: every attack record of `run_dir` (or those `names`; with
    `only_failures` only those whose ego collided from t0, the judge's failures) as
    OUT/<scene>.xml + OUT/<scene>.json (`write_commonroad`), with `plot` also OUT/<scene>.png at
    the collision step (`render_png`). OUT/export.json holds the settings, OUT/index.json what
    was exported and what was skipped with why. A scene counts once its sidecar is written;
    `resume` goes on where a run stopped (same settings only)."""
    from adversary.crash.scenes import load_record
    from riskmap.infra.atomic import write_json
    from riskmap.infra.rundir import claim_out_dir

    run_dir, out = Path(run_dir), export_target(fmt, out)
    meta = read_attack_run(run_dir)
    scenes_dir = scenes_of(run_dir, meta, scenes)
    records = sorted((run_dir / "attacks").glob("*.json"))
    if names:
        known = {p.stem for p in records}
        missing = [n for n in names if n not in known]
        if missing:
            raise InputError(f"--scene {missing[0]} is not an attack of {run_dir}; pick one of "
                             f"{', '.join(sorted(known)[:5])}{', ...' if len(known) > 5 else ''}")
        records = [p for p in records if p.stem in names]
    if not records:
        raise InputError(f"--run {run_dir} holds no attack records yet; wait for `adversary attack` to "
                         "write some")
    settings = {"run": str(run_dir), "format": fmt, "only_failures": bool(only_failures),
                "scenes": str(scenes_dir), "names": list(names), "plot": bool(plot)}
    claim_out_dir(out, holds="an export", marker=None, resume=resume, settings_file="export.json",
                  settings=settings)
    index = {"exported": [], "skipped": []}
    for i, path in enumerate(records):
        name = path.stem
        try:
            attack = json.loads(path.read_text())
        except (OSError, ValueError):
            index["skipped"].append({"scene": name, "why": "the attack record is unreadable"})
            continue
        metrics = attack.get("metrics") or {}
        why = None
        if attack.get("status") != "ok":
            why = f"status {attack.get('status')}: no attacked run"
        elif only_failures and metrics.get("failure") is None:
            why = "no collision of the ego from t0 (--only-failures)"
        if why:
            index["skipped"].append({"scene": name, "why": why})
            continue
        entry = {"scene": name, "xml": f"{name}.xml", "sidecar": f"{name}.json",
                 "collision": bool(attack.get("collision")),
                 "counts": bool((metrics.get("failure") or {}).get("counts"))}
        if not (resume and (out / f"{name}.json").is_file()):
            record = load_record(scenes_dir / f"{name}.npz")
            write_commonroad(attack, record, out, name)
        add_exported(entry, name, out, index, plot, resume)
        if progress:
            print(f"[{i + 1}/{len(records)}] {name} -> {out / entry['xml']}", flush=True)
    write_json(out / "index.json", {**settings, **index})
    return index
