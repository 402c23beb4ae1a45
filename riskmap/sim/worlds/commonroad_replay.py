"""Log-replay closed loop on a CommonRoad recording: any `Planner` drives one recorded vehicle.

The road is a highway-env `RoadNetwork` of `PolyLane`s built from the lanelets (centre line and
both bounds, in highway-env's y-down frame), so the ego moves with highway-env's bicycle model
and the same tracking controller as `riskmap drive`. Every other vehicle follows its recording:
in `log` mode by time (it does not react to the ego), in `reactive` mode along its recorded path
with its own progress, braking for an ego in its way (`ReactiveTraffic`); collisions are box
overlaps against the others' boxes.

At `start_s` the recorded vehicle is handed over to the planner, which replans at `replan_hz`
from a 2 s history (the human's own before the hand-over, its closed-loop states after) and the
recorded traffic; the episode runs until the vehicle's recording ends (or `duration_s`), a
collision, or the ego leaving the lanes. Metrics are those of `riskmap drive` plus the error
against the recorded human: ADE over the episode and goal error (distance to where the human
was at the end).

Traffic lights (recordings with signals, `rasterize.commonroad.LaneletLight`): the planner's
scene carries them (`Scene.signals`) and its route waits at red lights. `red_light_violations`
counts the times the ego's front crossed the stop line of a lane it was on while the light
governing its turn was red (amber counts as red), once per crossing (`red_light_events`); a
light on a lane the ego does not drive on never counts. The turn is the one the ego then made
(the successor lanelet holding most of its later positions; the recorded vehicle's when the
episode ends first; unknown at a lanelet without successors, where the crossing is red only if
no light of the stop line is green). The recorded human's own count over the same time is
`human_red_light_violations` (NGSIM drivers cross on amber, and turn right on red, which
California allows after a stop: the reference, not zero).
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rasterize.commonroad.config import CommonRoadSceneConfig
from rasterize.commonroad.lanes import lanes_from_lanelets
from rasterize.commonroad.lights import governing, movement_red, turn_between
from rasterize.commonroad.reader import load_scenario
from rasterize.commonroad.tracks import RecordedTraffic
from rasterize.errors import InputError
from rasterize.frames import (
    box_corners,
    ego_from_world,
    heading_from_highway_env,
    highway_env_from_world,
    world_from_highway_env,
)
from rasterize.geometry import box_gap
from rasterize.scene import STATE_DIM, Scene
from rasterize.timebase import CONTROL_HZ, HISTORY_S, REPLAN_HZ
from rasterize.tracks import Tracks
from riskmap.sim.loop.control import planned_vehicle_class
from riskmap.sim.records.metrics import (
    SafetyConfig,
    centre_off_lane,
    dangerous_encounters,
    safety_pct,
    stop_line_crossings,
)
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS, Plan, traits_of
from riskmap.sim.drivers.reactive_traffic import ReactiveTraffic
from riskmap.sim.records.record import EpisodeRecord
from riskmap.sim.loop.rollout import LoopConfig, check_replan_hz, drive_world

GOALS = ("route", "human")
MODES = ("log", "reactive")


@dataclass(frozen=True)
class ReplayConfig:
    control_hz: int = CONTROL_HZ
    replan_hz: int = REPLAN_HZ
    history_s: float = HISTORY_S
    gap_radius_m: float = 40.0        # others farther than this do not count for the min gap
    off_road_margin_m: float = 1.0    # beyond the outer lane edge by this much = off the road
    goal: str = "route"               # route: the route rule (what a deployed planner knows);
                                      # human: the recorded vehicle's own end (the paper's Table I)
    mode: str = "log"                 # log: the others replay their tracks by time; reactive: they
                                      # keep their paths but brake for the ego (`ReactiveTraffic`)

    def __post_init__(self) -> None:
        check_replan_hz(self.replan_hz, self.control_hz)
        if self.goal not in GOALS:
            raise InputError(f"--goal {self.goal!r} is unknown; use one of {', '.join(GOALS)}")
        if self.mode not in MODES:
            raise InputError(f"--mode {self.mode!r} is unknown; use one of {', '.join(MODES)}")


def road_from_lanelets(network):
    """A highway-env `Road` whose lanes are the lanelets (one edge of the graph per lanelet)."""
    from highway_env.road.lane import PolyLane
    from highway_env.road.road import Road, RoadNetwork

    graph = RoadNetwork()
    for lane in lanes_from_lanelets(network):
        graph.add_lane(f"{id(lane)}:in", f"{id(lane)}:out", PolyLane(
            [tuple(p) for p in highway_env_from_world(lane.centre)],
            [tuple(p) for p in highway_env_from_world(lane.left)],
            [tuple(p) for p in highway_env_from_world(lane.right)],
            line_types=(int(lane.left_line), int(lane.right_line))))   # same codes as highway-env
    return Road(network=graph, np_random=np.random.RandomState(0), record_history=False)


class RecordedFuturePlanner:
    """`replay`: plans what the recorded vehicle did next, from wherever the ego is now.

    The recorded future displacements, in the recorded vehicle's own frame at this time, become
    the waypoints in the ego's frame: the human's speed profile and path shape, never waypoints
    behind an ego that has drifted ahead of the log (which a plan of the logged positions would
    give and the tracking controller would chase). Past the end of the recording the vehicle
    is extrapolated at its last speed and heading.
    """

    def __init__(self, traffic: RecordedTraffic, obstacle_id: int):
        self.traffic, self.agent = traffic, traffic.index_of(obstacle_id)

    def reset(self, scene: Scene) -> None:
        pass

    def plan(self, scene: Scene) -> Plan:
        times = scene.time_s + PLAN_DT_S * np.arange(0, PLAN_STEPS + 1)
        xy, heading = recorded_positions(self.traffic, self.agent, times)
        return Plan(ego_from_world(xy[1:], xy[0], heading))


def recorded_positions(traffic: RecordedTraffic, agent: int, times_s: np.ndarray) -> tuple[np.ndarray, float]:
    """World positions [len(times_s), 2] of a recorded vehicle at increasing `times_s` (past the
    end of its record: extrapolated at its last speed and heading) and its heading (rad) at the
    first time, which must lie inside the record."""
    _, last = traffic.span(agent)
    end = last * traffic.dt_s
    states, valid = traffic.resample(np.array([agent]), np.minimum(times_s, end))
    if not valid[0, 0]:
        raise InputError(f"vehicle {traffic.ids[agent]} is not recorded at {times_s[0]:g} s")
    xy = states[0, :, :2] + np.maximum(times_s - end, 0.0)[:, None] * (
        states[0, -1, 4] * states[0, -1, 2:4])
    return xy, float(np.arctan2(states[0, 0, 3], states[0, 0, 2]))


def _ego_scene(traffic: RecordedTraffic, ego: int, track_t: list[float], track: list[np.ndarray],
               now_s: float, lanes, config: CommonRoadSceneConfig, others_at) -> Scene:
    """The scene the planner sees now: the ego's track (no future) and the others' states so far
    (`others_at(agents, times)`: the world's `CommonRoadWorld.others_at`)."""
    ego_state = track[-1]
    others = [a for a in range(len(traffic.ids)) if a != ego]
    present_states, present = others_at(np.array(others, dtype=np.int64), np.array([now_s]))
    dist = np.linalg.norm(present_states[:, 0, :2] - ego_state[:2], axis=1)
    order = [others[i] for i in np.argsort(dist, kind="stable")
             if present[i, 0] and dist[i] <= config.radius_m][: config.max_agents - 1]
    times = now_s + config.dt_s * np.arange(-config.history_steps, 1)
    states, valid = others_at(np.array(order, dtype=np.int64), times)
    t_arr, s_arr = np.asarray(track_t), np.asarray(track)
    angle = np.unwrap(np.arctan2(s_arr[:, 3], s_arr[:, 2]))
    mine_valid = (times >= t_arr[0] - 1e-9) & (times <= t_arr[-1] + 1e-9)
    theta = np.interp(times, t_arr, angle)
    mine = np.column_stack([np.interp(times, t_arr, s_arr[:, 0]), np.interp(times, t_arr, s_arr[:, 1]),
                            np.cos(theta), np.sin(theta), np.interp(times, t_arr, s_arr[:, 4]),
                            np.interp(times, t_arr, s_arr[:, 5])])
    agents = np.array([ego] + order, dtype=np.int64)
    route = traffic.route(ego, ego_state, states[:, -1].reshape(-1, STATE_DIM),
                          traffic.sizes[order, 0], now_s, config)
    return Scene(np.concatenate([mine[None], states.reshape(-1, len(times), STATE_DIM)]),
                 np.concatenate([mine_valid[None], valid.reshape(-1, len(times))]),
                 traffic.sizes[agents], traffic.kinds[agents], ego_index=0,
                 current_index=config.history_steps, dt=config.dt_s, lanes=lanes,
                 source=f"commonroad:{traffic.name}", time_s=now_s, route_xy=route,
                 signals=traffic.scene_signals(ego_state, now_s, config),
                 agent_ids=np.asarray(traffic.ids, dtype=np.int64)[agents])


class CommonRoadWorld:
    """Recorded vehicle `ego_id` of `traffic`, planner-driven from `start_s` among the replayed
    others: a `riskmap.sim.loop.world.World` (module docstring).

    The ego's track (`track_t` s, `track` [6] world states) is the recorded history up to the
    hand-over, then the closed loop; `driven()` is the closed-loop part. `n_steps`: steps to the
    end of the recording (or of `duration_s`). `collision` names the vehicle that was hit. Where
    the others are is `others_at`, whatever the mode; everything here reads them from it.
    """

    def __init__(self, traffic: RecordedTraffic, ego_id: int, start_s: float | None = None,
                 duration_s: float | None = None, config: ReplayConfig = ReplayConfig(),
                 scene_config: CommonRoadSceneConfig | None = None):
        self.traffic, self.config = traffic, config
        self.scene_config = scene_config or CommonRoadSceneConfig()
        self.ego_id, self.ego_index = int(ego_id), traffic.index_of(ego_id)
        ego = self.ego_index
        self.dt = 1.0 / config.control_hz
        self.start, self.n_steps = self._span(start_s, duration_s)
        hist_t = np.arange(max(traffic.span(ego)[0] * traffic.dt_s, self.start - config.history_s),
                           self.start + 1e-9, self.dt)
        hist, _ = traffic.resample(np.array([ego]), hist_t)
        self.track_t, self.track = list(hist_t), list(hist[0])
        self.history_len = len(hist_t)
        self.road = self._build_road()
        self.lanes = lanes_from_lanelets(traffic.scenario.lanelet_network)
        self.vehicle = self._planned_vehicle(self.track[-1])
        self.others = np.array([a for a in range(len(traffic.ids)) if a != ego], dtype=np.int64)
        self.reactive = (ReactiveTraffic(traffic, self.others, ego, self.start, self.dt)
                         if config.mode == "reactive" else None)
        self.steps = 0
        self.crashed = self.off_network = False
        self.collision: dict | None = None
        self._gaps: dict[float, list] = {}        # radius -> this step's (gap, agent, xy) near

    def _build_road(self):
        """The highway-env road of the lanelets (a subclass may reuse one built before)."""
        return road_from_lanelets(self.traffic.scenario.lanelet_network)

    def _span(self, start_s: float | None, duration_s: float | None) -> tuple[float, int]:
        first, last = self.traffic.span(self.ego_index)
        t_first, t_last = first * self.traffic.dt_s, last * self.traffic.dt_s
        start = t_first + self.config.history_s if start_s is None else float(start_s)
        if not t_first <= start < t_last:
            raise InputError(f"start {start:g} s is outside vehicle {self.ego_id}'s "
                             f"recording ({t_first:g}-{t_last:g} s of {self.traffic.name})")
        end = t_last if duration_s is None else min(t_last, start + float(duration_s))
        return start, int(np.floor((end - start) / self.dt + 1e-9))

    def _planned_vehicle(self, now: np.ndarray):
        vehicle = planned_vehicle_class()(self.road, highway_env_from_world(now[:2]),
                                          float(-np.arctan2(now[3], now[2])), float(now[4]))
        vehicle.LENGTH, vehicle.WIDTH = self.traffic.sizes[self.ego_index]
        vehicle.action = {"acceleration": 0.0, "steering": 0.0}
        self.road.vehicles = [vehicle]        # the others are recorded boxes, not road vehicles
        return vehicle

    @property
    def ego(self):
        return self.vehicle

    @property
    def time_s(self) -> float:
        return self.start + self.steps * self.dt

    @property
    def done(self) -> bool:
        return self.crashed or self.off_network or self.steps >= self.n_steps

    def hand_over(self, history_s: float) -> tuple[object, Scene]:
        """The recorded vehicle is planner-driven from the start; the planner is reset now."""
        return self.vehicle, self.scene(history_s)

    def scene(self, history_s: float) -> Scene:
        """The planner's scene now; its history is `scene_config`'s, as for collected windows.

        With `config.goal == "human"` the route is the straight line from the ego to where the
        recorded vehicle is at the end of the plan's horizon (6 s from now; past the end of its
        record, extrapolated at its last speed and heading), so the route rule's goal (the last
        route point inside the grid) is the human's position then, as for a training window with
        the demonstration's goal. A goal fixed at the record's end would ask every later replan to
        take 6 s for what the human did in less, and the ego would trail the human to the end."""
        scene = _ego_scene(self.traffic, self.ego_index, self.track_t, self.track, self.time_s,
                           self.lanes, self.scene_config, self.others_at)
        if self.config.goal == "human":
            target, _ = recorded_positions(self.traffic, self.ego_index,
                                           np.array([self.start, self.time_s + PLAN_STEPS * PLAN_DT_S]))
            line = np.linspace(self.track[-1][:2], target[-1], 200)
            scene = dataclasses.replace(scene, route_xy=line)
        return scene

    def ego_state(self) -> np.ndarray:
        return self.track[-1]

    def cap_ego_accel(self, cap) -> None:
        self.vehicle.accel_cap = cap

    def history(self, history_s: float, dt_s: float, radius_m: float) -> Scene:
        config = dataclasses.replace(self.scene_config, history_s=history_s, dt_s=dt_s, radius_m=radius_m)
        return _ego_scene(self.traffic, self.ego_index, self.track_t, self.track, self.time_s, None,
                          config, self.others_at)

    def others_at(self, agents: np.ndarray, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States [len(agents), len(times_s), 6] and presence of other vehicles (indices into
        `traffic`) at times up to now: their recording in log mode, where they drove in reactive
        mode (at the world's steps, or before the hand-over)."""
        if self.reactive is None:
            return self.traffic.resample(agents, times_s)
        return self.reactive.states_at(agents, times_s)

    def driven(self) -> tuple[np.ndarray, np.ndarray]:
        """Times [S] and world states [S, 6] of the closed-loop steps."""
        return (np.asarray(self.track_t[self.history_len:]),
                np.asarray(self.track[self.history_len:]).reshape(-1, STATE_DIM))

    def step(self) -> None:
        if self.reactive is not None:          # the others react to where the ego is now
            self.reactive.step(self.track[-1])
        state = self._move_ego()
        self.steps += 1
        self.track_t.append(self.time_s)
        self.track.append(state)
        xy, heading = state[:2], float(np.arctan2(state[3], state[2]))
        self._gaps = {}
        near = self._near(self.config.gap_radius_m)
        if near and min(gap for gap, _, _ in near) <= 0.0:
            self.crashed = True
            _, agent, other_xy = near[int(np.argmin([gap for gap, _, _ in near]))]
            # Log-replayed traffic does not react: a vehicle behind may run into an ego that
            # drives slower than the human did. Say which it was.
            self.collision = {"other_id": int(self.traffic.ids[agent]), "other_ahead": bool(
                ego_from_world(other_xy, xy, heading)[0] > 0), "failure": self.classify_collision(agent)}
            return
        if centre_off_lane(self.road, self.vehicle, self.config.off_road_margin_m):
            self.off_network = True

    def classify_collision(self, agent: int, radius_m: float = 80.0) -> dict:
        """`riskmap.sim.records.failures.classify_failure` of the ego's collision with `agent` (an index
        into `traffic`) now, over the drive so far (history included) and every vehicle within
        `radius_m` now; lane changes are not tried (longitudinal alternatives only)."""
        from riskmap.sim.records.failures import classify_failure

        times = np.asarray(self.track_t)
        ego = np.asarray(self.track).reshape(-1, STATE_DIM)
        now, present = self.others_at(self.others, times[-1:])
        near = [a for i, a in enumerate(self.others)
                if present[i, 0] and np.linalg.norm(now[i, 0, :2] - ego[-1, :2]) < radius_m]
        near = list(dict.fromkeys([int(agent), *near]))
        others, valid = self.others_at(np.array(near), times)
        states = np.concatenate([ego[None], others])
        valid = np.concatenate([np.ones((1, len(times)), bool), valid])
        sizes = np.concatenate([self.traffic.sizes[[self.ego_index]], self.traffic.sizes[near]])
        kinds = np.concatenate([self.traffic.kinds[[self.ego_index]], self.traffic.kinds[near]])
        return classify_failure(Tracks(states, valid, sizes, kinds), 0, 1, len(times) - 1, self.dt,
                                from_step=self.history_len - 1)

    def _move_ego(self) -> np.ndarray:
        """One `dt` of the highway-env ego; its world state [6] afterwards."""
        prev = self.track[-1]
        self.road.act()
        self.road.step(self.dt)
        xy = world_from_highway_env(self.vehicle.position)
        heading = float(heading_from_highway_env(self.vehicle.heading))
        prev_heading = float(np.arctan2(prev[3], prev[2]))
        yaw_rate = ((heading - prev_heading + np.pi) % (2 * np.pi) - np.pi) / self.dt
        return np.array([xy[0], xy[1], np.cos(heading), np.sin(heading),
                         float(self.vehicle.speed), yaw_rate])

    def _near(self, radius_m: float) -> list[tuple[float, int, np.ndarray]]:
        """(box gap, agent, position) of every other vehicle present within `radius_m` now."""
        if radius_m not in self._gaps:
            me_state, traffic = self.track[-1], self.traffic
            rec, present = self.others_at(self.others, np.array([self.time_s]))
            me = box_corners(me_state[:2], me_state[2:4], *traffic.sizes[self.ego_index])
            self._gaps[radius_m] = [
                (box_gap(me, box_corners(rec[i, 0, :2], rec[i, 0, 2:4], *traffic.sizes[a])), a,
                 rec[i, 0, :2])
                for i, a in enumerate(self.others)
                if present[i, 0] and np.linalg.norm(rec[i, 0, :2] - me_state[:2]) < radius_m]
        return self._gaps[radius_m]

    def min_gap(self, radius_m: float) -> float:
        return min((gap for gap, _, _ in self._near(radius_m)), default=float("inf"))


def _turn_taken(traffic: RecordedTraffic, agent: int, lanelet_id: int, times_s: np.ndarray,
                states: np.ndarray, after_s: float) -> str | None:
    """The turn vehicle `agent` made out of `lanelet_id` after `after_s`: into the successor
    holding most of its positions after then, else the recorded vehicle's successor, else None
    (no successor, or neither reached one)."""
    network = traffic.scenario.lanelet_network
    successors = [int(s) for s in network.find_lanelet_by_id(lanelet_id).successor]
    if not successors:
        return None
    if len(successors) == 1:
        return turn_between(network, lanelet_id, successors[0])
    later = [p for p in np.asarray(states)[np.asarray(times_s) > after_s, :2]]
    counts = Counter(int(i) for ids in (network.find_lanelet_by_position(later) if later else [])
                     for i in ids if int(i) in successors)
    if not counts:
        recorded = traffic.lanelet_counts(agent)
        if not any(recorded.get(s, 0) for s in successors):
            return None
        return turn_between(network, lanelet_id, traffic.successor_taken(agent, successors))
    best = max(sorted(counts), key=lambda s: (counts[s], -s))
    return turn_between(network, lanelet_id, best)


def red_light_events(traffic: RecordedTraffic, agent: int, times_s: np.ndarray,
                     states: np.ndarray) -> list[dict]:
    """Every crossing of a signalised stop line by the front of vehicle `agent` (sizes from
    `traffic`) driving `states` [T, 6] at `times_s` [T] (s from the recording's step 0), in time
    order: lanelet id, time, the turn made, the governing lights' states and whether that was a
    red-light violation (module doc)."""
    events = []
    length = float(traffic.sizes[agent, 0])
    for lanelet_id, lights in sorted(traffic.lights_by_lanelet.items()):
        for t in stop_line_crossings(times_s, states, length, lights[0].stop_line, lights[0].forward):
            turn = _turn_taken(traffic, agent, lanelet_id, times_s, states, t)
            governed = governing(lights, turn)
            events.append({
                "lanelet": int(lanelet_id), "time_s": round(float(t), 2), "turn": turn,
                "lights": {str(light.light_id): str(light.state_at(np.array([t]))[0]) for light in governed},
                "red": bool(governed) and movement_red(governed, t)})
    return sorted(events, key=lambda e: e["time_s"])


def _human_metrics(world: CommonRoadWorld) -> dict:
    """Error against the recorded human, its distance, and Safety % over the driven steps."""
    traffic, ego = world.traffic, world.ego_index
    driven_t, driven = world.driven()
    human, _ = traffic.resample(np.array([ego]), driven_t)
    errors = [float(np.linalg.norm(mine - recorded))
              for mine, recorded in zip(driven[:, :2], human[0, :, :2])]
    # Safety % as on simulated scenes (riskmap.sim.records.metrics): every driven step, every other recorded
    # vehicle within the encounter radius is an encounter, dangerous when close or about to touch.
    other_states, other_present = world.others_at(world.others, driven_t)
    dangerous, encounters = dangerous_encounters(driven, np.asarray(traffic.sizes[ego]), other_states,
                                                 other_present, np.asarray(traffic.sizes)[world.others],
                                                 SafetyConfig())
    human_t = np.asarray(world.track_t[world.history_len - 1:])
    human_path, _ = traffic.resample(np.array([ego]), human_t)
    human_events = red_light_events(traffic, ego, human_t, human_path[0]) if traffic.lights else []
    return {
        "human_red_light_violations": sum(e["red"] for e in human_events),
        "human_distance_m": float(np.linalg.norm(np.diff(human_path[0, :, :2], axis=0), axis=1).sum()),
        "dangerous": dangerous, "encounters": encounters,
        "safety_pct": safety_pct(dangerous, encounters),
        "ade_m": float(np.mean(errors)) if errors else 0.0,
        "goal_error_m": errors[-1] if errors else 0.0,
    }


def route_scene_config(planner, base: CommonRoadSceneConfig | None = None) -> CommonRoadSceneConfig:
    """What `planner` sees of a recording: `base` (default settings) with the route rule the
    planner was trained with, when it declares one (`route_settings`: a planner trained on
    recorded traffic sends itself as far as the recorded drivers went, not at highway-env's
    speeds)."""
    base = base or CommonRoadSceneConfig()
    settings = traits_of(planner).route_settings
    if not settings:
        return base
    return dataclasses.replace(base, speed_limit_mps=settings["speed_limit_mps"],
                               route_rule=dataclasses.replace(base.route_rule,
                                                              accel_mps2=settings["route_accel_mps2"]))


def replay_commonroad_episode(scenario_path, ego_id: int, planner, start_s: float | None = None,
                              duration_s: float | None = None, config: ReplayConfig | None = None,
                              scene_config: CommonRoadSceneConfig | None = None) -> dict:
    """Drive recorded vehicle `ego_id` of a CommonRoad file with `planner`; returns its
    `EpisodeRecord` as a dict (extras: scenario, ego_id, start_s, collision and `_human_metrics`).

    `scenario_path`: a .xml path or a `RecordedTraffic`. `start_s` defaults to the vehicle's first
    time with `config.history_s` of history; the episode ends with its recording (or after
    `duration_s`). `scene_config` sets what the planner sees (as for collected windows); by
    default `route_scene_config(planner)`.
    """
    config = config or ReplayConfig()
    traffic = (scenario_path if isinstance(scenario_path, RecordedTraffic)
               else RecordedTraffic(load_scenario(scenario_path), Path(scenario_path).stem))
    world = CommonRoadWorld(traffic, ego_id, start_s, duration_s, config,
                            scene_config or route_scene_config(planner))
    loop = drive_world(world, planner, LoopConfig(world.n_steps, config.control_hz // config.replan_hz,
                                                  config.history_s, config.gap_radius_m))
    human = _human_metrics(world)
    # From the hand-over on: a crossing between the last human step and the first driven one is
    # the ego's.
    driven_t = np.asarray(world.track_t[world.history_len - 1:])
    driven = np.asarray(world.track[world.history_len - 1:]).reshape(-1, STATE_DIM)
    events = red_light_events(traffic, world.ego_index, driven_t, driven) if traffic.lights else []
    record = EpisodeRecord.measured(
        type(planner).__name__, world.crashed, world.off_network, round(world.time_s - world.start, 3),
        loop.distance_m, loop.speeds, loop.gaps, loop.plan_times_s,
        extra={"scenario": traffic.name, "ego_id": int(ego_id), "start_s": round(world.start, 3),
               "collision": world.collision, "signal_crossings": events, **human},
        red_light_violations=sum(e["red"] for e in events), **loop.implausible.fields())
    return record.as_dict()
