"""Log-replay closed loop on a CommonRoad recording: any `Planner` drives one recorded vehicle.

The road is a highway-env `RoadNetwork` of `PolyLane`s built from the lanelets (centre line and
both bounds, in highway-env's y-down frame), so the ego moves with highway-env's bicycle model
and the same tracking controller as `riskmap drive`. Every other vehicle replays its recording
(it does not react to the ego); collisions are box overlaps against the recorded boxes.

At `start_s` the recorded vehicle is handed over to the planner, which replans at `replan_hz`
from a 2 s history (the human's own before the hand-over, its closed-loop states after) and the
recorded traffic; the episode runs until the vehicle's recording ends (or `duration_s`), a
collision, or the ego leaving the lanes. Metrics are those of `riskmap drive` plus the error
against the recorded human: ADE over the episode and goal error (distance to where the human
was at the end).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rasterize.commonroad import (
    CommonRoadSceneConfig,
    RecordedTraffic,
    lanes_from_lanelets,
    load_scenario,
    route_on_lanelets,
)
from rasterize.errors import InputError
from rasterize.frames import (
    box_corners,
    ego_from_world,
    ego_pose,
    heading_from_highway_env,
    highway_env_from_world,
    world_from_highway_env,
)
from rasterize.geometry import box_gap
from rasterize.scene import STATE_DIM, Scene
from riskmap.sim.control import ControllerConfig, TrackingController, planned_vehicle_class
from riskmap.sim.episode import _off_network
from riskmap.sim.metrics import SafetyConfig, dangerous_encounters, safety_pct
from riskmap.sim.plan import PLAN_DT_S, PLAN_STEPS, Plan, check_plan


@dataclass(frozen=True)
class ReplayConfig:
    control_hz: int = 10
    replan_hz: int = 2
    history_s: float = 2.0
    gap_radius_m: float = 40.0        # others farther than this do not count for the min gap
    off_road_margin_m: float = 1.0    # beyond the outer lane edge by this much = off the road

    def __post_init__(self) -> None:
        if self.control_hz % self.replan_hz:
            raise InputError("control_hz must be a multiple of replan_hz")


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
        _, last = self.traffic.span(self.agent)
        end = last * self.traffic.dt_s
        states, valid = self.traffic.resample(np.array([self.agent]), np.minimum(times, end))
        if not valid[0, 0]:
            raise InputError(f"replay: vehicle {self.traffic.ids[self.agent]} is not recorded at "
                             f"{scene.time_s:g} s")
        xy = states[0, :, :2] + np.maximum(times - end, 0.0)[:, None] * (
            states[0, -1, 4] * states[0, -1, 2:4])
        heading = float(np.arctan2(states[0, 0, 3], states[0, 0, 2]))
        return Plan(ego_from_world(xy[1:], xy[0], heading))


def _ego_scene(traffic: RecordedTraffic, ego: int, track_t: list[float], track: list[np.ndarray],
               now_s: float, lanes, config: CommonRoadSceneConfig) -> Scene:
    """The scene the planner sees now: the ego's track (no future) and the recorded others."""
    ego_state = track[-1]
    others = [a for a in range(len(traffic.ids)) if a != ego]
    present_states, present = traffic.resample(np.array(others, dtype=np.int64), np.array([now_s]))
    dist = np.linalg.norm(present_states[:, 0, :2] - ego_state[:2], axis=1)
    order = [others[i] for i in np.argsort(dist, kind="stable")
             if present[i, 0] and dist[i] <= config.radius_m][: config.max_agents - 1]
    times = now_s + config.dt_s * np.arange(-config.history_steps, 1)
    states, valid = traffic.resample(np.array(order, dtype=np.int64), times)
    t_arr, s_arr = np.asarray(track_t), np.asarray(track)
    angle = np.unwrap(np.arctan2(s_arr[:, 3], s_arr[:, 2]))
    mine_valid = (times >= t_arr[0] - 1e-9) & (times <= t_arr[-1] + 1e-9)
    theta = np.interp(times, t_arr, angle)
    mine = np.column_stack([np.interp(times, t_arr, s_arr[:, 0]), np.interp(times, t_arr, s_arr[:, 1]),
                            np.cos(theta), np.sin(theta), np.interp(times, t_arr, s_arr[:, 4]),
                            np.interp(times, t_arr, s_arr[:, 5])])
    agents = np.array([ego] + order, dtype=np.int64)
    route = route_on_lanelets(traffic.scenario.lanelet_network, ego_state, traffic.sizes[ego, 0],
                              states[:, -1].reshape(-1, STATE_DIM), traffic.sizes[order, 0],
                              config.route_rule, config.speed_limit_mps)
    return Scene(np.concatenate([mine[None], states.reshape(-1, len(times), STATE_DIM)]),
                 np.concatenate([mine_valid[None], valid.reshape(-1, len(times))]),
                 traffic.sizes[agents], traffic.kinds[agents], ego_index=0,
                 current_index=config.history_steps, dt=config.dt_s, lanes=lanes,
                 source=f"commonroad:{traffic.name}", time_s=now_s, route_xy=route)


def replay_commonroad_episode(scenario_path, ego_id: int, planner, start_s: float | None = None,
                              duration_s: float | None = None, config: ReplayConfig | None = None,
                              scene_config: CommonRoadSceneConfig | None = None) -> dict:
    """Drive recorded vehicle `ego_id` of a CommonRoad file with `planner`; returns metrics.

    `scenario_path`: a .xml path or a `RecordedTraffic`. `start_s` defaults to the vehicle's first
    time with `config.history_s` of history; the episode ends with its recording (or after
    `duration_s`). `scene_config` sets what the planner sees (as for collected windows).
    """
    config = config or ReplayConfig()
    scene_config = scene_config or CommonRoadSceneConfig()
    traffic = (scenario_path if isinstance(scenario_path, RecordedTraffic)
               else RecordedTraffic(load_scenario(scenario_path), Path(scenario_path).stem))
    ego = traffic.index_of(ego_id)
    first, last = traffic.span(ego)
    dt = 1.0 / config.control_hz
    t_first, t_last = first * traffic.dt_s, last * traffic.dt_s
    start = t_first + config.history_s if start_s is None else float(start_s)
    if not t_first <= start < t_last:
        raise InputError(f"start {start:g} s is outside vehicle {ego_id}'s recording "
                         f"({t_first:g}-{t_last:g} s of {traffic.name})")
    end = t_last if duration_s is None else min(t_last, start + float(duration_s))
    n_steps = int(np.floor((end - start) / dt + 1e-9))

    # The ego's track: the recorded history up to the hand-over, then the closed loop.
    hist_t = np.arange(max(t_first, start - config.history_s), start + 1e-9, dt)
    hist, _ = traffic.resample(np.array([ego]), hist_t)
    track_t, track = list(hist_t), list(hist[0])
    road = road_from_lanelets(traffic.scenario.lanelet_network)
    lanes = lanes_from_lanelets(traffic.scenario.lanelet_network)
    now = track[-1]
    vehicle = planned_vehicle_class()(
        road, highway_env_from_world(now[:2]), float(-np.arctan2(now[3], now[2])), float(now[4]))
    vehicle.LENGTH, vehicle.WIDTH = traffic.sizes[ego]
    vehicle.action = {"acceleration": 0.0, "steering": 0.0}
    road.vehicles = [vehicle]
    controller = TrackingController(ControllerConfig())
    replan_every = config.control_hz // config.replan_hz
    plan_times, gaps, errors, speeds = [], [], [], []
    collided = off_road = False
    collision = None
    distance, since_plan, t = 0.0, 0.0, start
    others = np.array([a for a in range(len(traffic.ids)) if a != ego], dtype=np.int64)
    planner.reset(_ego_scene(traffic, ego, track_t, track, t, lanes, scene_config))
    for k in range(n_steps):
        if k % replan_every == 0:
            scene = _ego_scene(traffic, ego, track_t, track, t, lanes, scene_config)
            started = time.perf_counter()
            plan = check_plan(planner.plan(scene), type(planner).__name__)
            plan_times.append(time.perf_counter() - started)
            controller.set_plan(plan.waypoints, *ego_pose(scene))
            since_plan = 0.0
        state = track[-1]
        accel, steer = controller.action(state[:2], float(np.arctan2(state[3], state[2])),
                                         float(state[4]), since_plan, dt)
        vehicle.command(accel, steer)
        since_plan += dt
        road.act()
        road.step(dt)
        t = start + (k + 1) * dt
        xy = world_from_highway_env(vehicle.position)
        heading = float(heading_from_highway_env(vehicle.heading))
        prev_heading = float(np.arctan2(state[3], state[2]))
        yaw_rate = ((heading - prev_heading + np.pi) % (2 * np.pi) - np.pi) / dt
        new = np.array([xy[0], xy[1], np.cos(heading), np.sin(heading), float(vehicle.speed), yaw_rate])
        distance += float(np.linalg.norm(new[:2] - state[:2]))
        track_t.append(t)
        track.append(new)
        speeds.append(float(vehicle.speed))
        human, _ = traffic.resample(np.array([ego]), np.array([t]))
        errors.append(float(np.linalg.norm(new[:2] - human[0, 0, :2])))
        rec, present = traffic.resample(others, np.array([t]))
        me = box_corners(new[:2], new[2:4], *traffic.sizes[ego])
        near = [(i, a) for i, a in enumerate(others)
                if present[i, 0] and np.linalg.norm(rec[i, 0, :2] - new[:2]) < config.gap_radius_m]
        step_gaps = [box_gap(me, box_corners(rec[i, 0, :2], rec[i, 0, 2:4], *traffic.sizes[a]))
                     for i, a in near]
        gaps.append(min(step_gaps, default=float("inf")))
        if gaps[-1] <= 0.0:
            collided = True
            i, a = near[int(np.argmin(step_gaps))]
            # Replayed traffic does not react: a vehicle behind may run into an ego that drives
            # slower than the human did. Say which it was.
            collision = {"other_id": int(traffic.ids[a]), "other_ahead": bool(
                ego_from_world(rec[i, 0, :2], new[:2], heading)[0] > 0)}
            break
        if _off_network(road, vehicle, config.off_road_margin_m):
            off_road = True
            break
    # Safety % as on simulated scenes (riskmap.sim.metrics): every driven step, every other recorded
    # vehicle within the encounter radius is an encounter, dangerous when close or about to touch.
    driven_t = np.asarray(track_t[len(hist_t):])
    driven = np.asarray(track[len(hist_t):]).reshape(-1, 6)
    other_states, other_present = traffic.resample(others, driven_t)
    dangerous, encounters = dangerous_encounters(driven, np.asarray(traffic.sizes[ego]), other_states,
                                                 other_present, np.asarray(traffic.sizes)[others],
                                                 SafetyConfig())
    human_path, _ = traffic.resample(np.array([ego]), np.asarray(track_t[len(hist_t) - 1:]))
    human_distance = float(np.linalg.norm(np.diff(human_path[0, :, :2], axis=0), axis=1).sum())
    return {
        "scenario": traffic.name, "ego_id": int(ego_id), "planner": type(planner).__name__,
        "start_s": round(start, 3), "simulated_s": round(t - start, 3),
        "collided": collided, "collision": collision, "off_road": off_road, "distance_m": distance,
        "human_distance_m": human_distance,
        "mean_speed_mps": float(np.mean(speeds)) if speeds else 0.0,
        "min_gap_m": float(min(gaps)) if gaps else float("inf"),
        "dangerous": dangerous, "encounters": encounters,
        "safety_pct": safety_pct(dangerous, encounters),
        "ade_m": float(np.mean(errors)) if errors else 0.0,
        "goal_error_m": errors[-1] if errors else 0.0,
        "plan_ms_median": 1000 * float(np.median(plan_times)) if plan_times else None,
        "plan_calls": len(plan_times),
    }
