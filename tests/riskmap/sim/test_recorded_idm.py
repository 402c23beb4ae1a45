"""`idm` on recordings: IDM + MOBIL along the recorded vehicle's lanelets (riskmap.sim.drivers.recorded_idm).

Lane geometry is checked against the fixture's lanelet centre lines with plain numpy here, not
with the module's own polyline code.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("commonroad")

from rasterize.commonroad import RecordedTraffic, load_scenario
from rasterize.errors import InputError
from rasterize.frames import world_from_ego
from rasterize.scene import Scene
from riskmap.planner.baselines import ConstantVelocityPlanner
from riskmap.sim.drivers.recorded_idm import (
    IdmMobilParams,
    LaneRoute,
    RecordedRouteIdmPlanner,
    idm_accel,
    recorded_lanelets,
)
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS
from riskmap.sim.loop.rollout import DriveHooks, LoopConfig, drive_world
from riskmap.sim.worlds.commonroad_replay import CommonRoadWorld, ReplayConfig, replay_commonroad_episode

RECORDING = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad" / "USA_US101-4_1_T-1.xml"
TIMES = PLAN_DT_S * np.arange(1, PLAN_STEPS + 1)
NO_CHANGES = IdmMobilParams(change_threshold_mps2=1e9)   # IDM only: MOBIL never pays


@pytest.fixture(scope="module")
def traffic() -> RecordedTraffic:
    return RecordedTraffic(load_scenario(RECORDING), RECORDING.stem)


def _lane(traffic, *lanelet_ids) -> np.ndarray:
    """The centre line through consecutive lanelets (their shared end points once)."""
    network = traffic.scenario.lanelet_network
    line = np.concatenate([network.find_lanelet_by_id(i).center_vertices for i in lanelet_ids])
    return line[np.concatenate([[True], np.linalg.norm(np.diff(line, axis=0), axis=1) > 1e-9])]


def _along(line: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arc length and signed lateral offset (left +) of points on a polyline (nearest segment)."""
    a, d = line[:-1], np.diff(line, axis=0)
    length = np.linalg.norm(d, axis=1)
    arc0 = np.concatenate([[0.0], np.cumsum(length)])
    arcs, lats = [], []
    for p in np.atleast_2d(xy):
        u = np.clip(((p - a) * d).sum(1) / length ** 2, 0.0, 1.0)
        k = int(np.argmin(np.linalg.norm(a + u[:, None] * d - p, axis=1)))
        rel = p - a[k] - u[k] * d[k]
        arcs.append(arc0[k] + u[k] * length[k])
        lats.append((d[k, 0] * rel[1] - d[k, 1] * rel[0]) / length[k])
    return np.array(arcs), np.array(lats)


def _point_at(line: np.ndarray, arc: float) -> tuple[np.ndarray, np.ndarray]:
    d = np.diff(line, axis=0)
    length = np.linalg.norm(d, axis=1)
    k = int(np.searchsorted(np.cumsum(length), arc))
    start = arc - np.concatenate([[0.0], np.cumsum(length)])[k]
    return line[k] + start * d[k] / length[k], d[k] / length[k]


def _scene(traffic, vehicle: int) -> Scene:
    return CommonRoadWorld(traffic, vehicle).scene(2.0)


def _alone(scene: Scene) -> Scene:
    """The scene with every other vehicle taken out: an empty road."""
    return dataclasses.replace(scene, states=scene.states[:1], valid=scene.valid[:1],
                               sizes=scene.sizes[:1], kinds=scene.kinds[:1],
                               agent_ids=None if scene.agent_ids is None else scene.agent_ids[:1])


def _with_leader(scene: Scene, lane: np.ndarray, ahead_m: float, speed: float) -> tuple[Scene, np.ndarray]:
    """An empty road but one vehicle `ahead_m` ahead of the ego on `lane`'s centre, at `speed`
    along it; returns the scene and the leader's state now."""
    alone = _alone(scene)
    arc, _ = _along(lane, alone.ego_state()[:2])
    xy, direction = _point_at(lane, float(arc[0]) + ahead_m)
    times = (np.arange(scene.states.shape[1]) - scene.current_index) * scene.dt
    leader = np.zeros((1, len(times), 6))
    leader[0, :, :2] = xy + times[:, None] * speed * direction
    leader[0, :, 2:4], leader[0, :, 4] = direction, speed
    return dataclasses.replace(
        alone, states=np.concatenate([alone.states, leader]),
        valid=np.concatenate([alone.valid, np.ones((1, len(times)), bool)]),
        sizes=np.concatenate([alone.sizes, [[4.5, 1.8]]]),
        kinds=np.concatenate([alone.kinds, alone.kinds[:1]]),
        agent_ids=None if alone.agent_ids is None else np.append(alone.agent_ids, alone.agent_ids.max() + 1)
    ), leader[0, scene.current_index]


def _plan_world(planner, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """A fresh plan's waypoints (ego frame) and the same points in the world."""
    planner.reset(scene)
    waypoints = planner.plan(scene).waypoints
    ego = scene.ego_state()
    return waypoints, world_from_ego(waypoints, ego[:2], float(np.arctan2(ego[3], ego[2])))


def test_the_idm_acceleration_is_the_textbook_formula():
    p = IdmMobilParams(desired_speed_mps=30.0, headway_s=1.5, min_gap_m=2.0, max_accel_mps2=1.5,
                       comfort_decel_mps2=2.0, delta=4.0, max_decel_mps2=6.0)
    # v = 10, gap 20 m to a leader at 8 m/s:
    #   s* = 2 + 10·1.5 + 10·2 / (2·sqrt(1.5·2)) = 17 + 10/sqrt(3) = 22.773502691896258
    #   (s*/20)^2 = (289 + 340/sqrt(3) + 100/3) / 400 = 1.2965810621445...
    #   a  = 1.5 (1 - (10/30)^4 - (s*/20)^2) = 1.5 (0.98765432098... - 1.29658106214...) = -0.46339011...
    s_star = 17.0 + 10.0 / math.sqrt(3.0)
    assert s_star == pytest.approx(22.773502691896258, abs=1e-12)
    expected = 1.5 * (1.0 - 1.0 / 81.0 - (s_star / 20.0) ** 2)
    assert expected == pytest.approx(-0.46339011173529, abs=1e-12)
    assert idm_accel(10.0, p, 20.0, 8.0) == pytest.approx(expected, abs=1e-12)
    assert idm_accel(10.0, p) == pytest.approx(1.5 * (1.0 - 1.0 / 81.0), abs=1e-12)    # free road
    assert idm_accel(30.0, p) == pytest.approx(0.0, abs=1e-12)                          # at v0
    # A leader pulling away fast: v T + v dv / (2 sqrt(a b)) = 15 - 200/sqrt(12) < 0, so s* = s0.
    assert idm_accel(10.0, p, 20.0, 30.0) == pytest.approx(1.5 * (1 - 1 / 81 - (2 / 20) ** 2), abs=1e-12)
    assert idm_accel(10.0, p, 0.1, 10.0) == -6.0                                        # capped braking
    with pytest.raises(InputError, match="desired_speed_mps"):
        IdmMobilParams(desired_speed_mps=0.0)


@pytest.mark.parametrize("vehicle", [442, 468, 475, 389])
def test_plans_are_finite_12_by_2_and_go_forward(traffic, vehicle):
    waypoints, _ = _plan_world(RecordedRouteIdmPlanner(traffic, vehicle), _scene(traffic, vehicle))
    assert waypoints.shape == (PLAN_STEPS, 2) and waypoints.dtype == np.float64
    assert np.isfinite(waypoints).all()
    assert (np.diff(np.concatenate([[0.0], waypoints[:, 0]])) >= 0.0).all()


def test_on_an_empty_road_it_speeds_up_along_the_lane_centre(traffic):
    scene = _alone(_scene(traffic, 475))
    speed = scene.ego_state()[4]                                  # 6.1 m/s
    waypoints, world = _plan_world(RecordedRouteIdmPlanner(traffic, 475), scene)
    steps = np.linalg.norm(np.diff(np.concatenate([[[0.0, 0.0]], waypoints]), axis=0), axis=1)
    speeds = steps / PLAN_DT_S
    assert (np.diff(speeds) > 0.0).all()                          # accelerating all the way
    assert speeds[0] > speed and speeds[-1] > speed + 6.0         # about 1.5 m/s² ...
    assert speeds[-1] < speed + 1.5 * 6.0 + 0.5                   # ... and never more
    # 475 drives lanelet 2 then 4: every waypoint is on that lane's centre, the last ones on it.
    _, lateral = _along(_lane(traffic, 2, 4), world)
    start_offset = abs(_along(_lane(traffic, 2, 4), scene.ego_state()[:2])[1][0])
    assert start_offset > 0.2                                     # it starts off the centre ...
    assert np.abs(lateral).max() <= start_offset + 0.05           # ... never drifts further
    assert np.abs(lateral[-6:]).max() < 0.05                      # ... and ends on it


def test_behind_a_slow_leader_it_keeps_its_gap(traffic):
    lane = _lane(traffic, 2, 4)
    scene, leader = _with_leader(_scene(traffic, 475), lane, ahead_m=25.0, speed=2.0)
    waypoints, world = _plan_world(RecordedRouteIdmPlanner(traffic, 475, NO_CHANGES), scene)
    predicted = leader[:2] + TIMES[:, None] * leader[4] * leader[2:4]
    half_lengths = 0.5 * (scene.sizes[0, 0] + scene.sizes[1, 0])
    gaps = np.linalg.norm(predicted - world, axis=1) - half_lengths
    assert gaps.min() >= NO_CHANGES.min_gap_m
    # it follows, rather than hanging back: slower than the leader's 2 m/s by the end is not needed
    speeds = np.linalg.norm(np.diff(np.concatenate([[[0.0, 0.0]], waypoints]), axis=0), axis=1) / PLAN_DT_S
    assert speeds[-1] < 4.0 and gaps[-1] < 15.0
    # The scene tells: holding the current speed would run into the leader.
    cv = world_from_ego(ConstantVelocityPlanner().plan(scene).waypoints, scene.ego_state()[:2],
                        float(np.arctan2(scene.ego_state()[3], scene.ego_state()[2])))
    assert (np.linalg.norm(predicted - cv, axis=1) - half_lengths).min() < NO_CHANGES.min_gap_m


def test_behind_a_slow_leader_mobil_changes_to_the_free_lane(traffic):
    lane = _lane(traffic, 2, 4)
    scene, _ = _with_leader(_scene(traffic, 475), lane, ahead_m=25.0, speed=2.0)
    planner = RecordedRouteIdmPlanner(traffic, 475)
    _, world = _plan_world(planner, scene)
    # 475 drives the leftmost lane (2): the free lane is lanelet 42 to its right.
    _, lateral = _along(lane, world)
    _, on_target = _along(_lane(traffic, 42, 40), world)
    assert lateral[-1] < -3.0 and abs(on_target[-1]) < 0.1
    # One move to the right, then along lane 42 (whose centre is not quite parallel to 2's).
    assert (np.diff(lateral[:5]) < -0.05).all() and (np.diff(lateral) < 0.06).all()
    start = _along(lane, scene.ego_state()[:2])[1][0]
    assert abs(lateral[0] - start) < 0.3                          # no jump at the start
    # The change stays committed: replanning half a second later keeps the same target.
    later = dataclasses.replace(scene, states=scene.states.copy())
    later.states[0, later.current_index, :2] = world[0]
    assert _along(_lane(traffic, 42, 40), world_from_ego(planner.plan(later).waypoints, world[0], float(
        np.arctan2(scene.ego_state()[3], scene.ego_state()[2]))))[1][-1] == pytest.approx(0.0, abs=0.1)


def test_changing_lanes_it_still_follows_the_leader_of_the_lane_it_leaves(traffic):
    # A car stopped 15 m ahead in lane 2, lane 42 free: MOBIL moves right, but along the blended
    # path the ego is out from behind the stopped car only metres later, so it must not close in.
    lane = _lane(traffic, 2, 4)
    scene, leader = _with_leader(_scene(traffic, 475), lane, ahead_m=15.0, speed=0.0)
    _, world = _plan_world(RecordedRouteIdmPlanner(traffic, 475), scene)
    arc, lateral = _along(lane, world)
    assert lateral[-1] < lateral[0] - 1.0                         # it is moving over ...
    half_lengths = 0.5 * (scene.sizes[0, 0] + scene.sizes[1, 0])
    gaps = _along(lane, leader[:2])[0][0] - half_lengths - arc
    assert gaps.min() >= NO_CHANGES.min_gap_m - 0.1               # ... behind the stopped car


def test_an_episode_runs_and_changes_lanes_without_hesitating(traffic):
    # 475 crawls behind 468 in the left lane; ConstantVelocity runs into 468 there.
    assert replay_commonroad_episode(traffic, 475, ConstantVelocityPlanner())["collided"]
    result = replay_commonroad_episode(traffic, 475, RecordedRouteIdmPlanner(traffic, 475),
                                       config=ReplayConfig())
    assert result["planner"] == "RecordedRouteIdmPlanner" and result["plan_calls"] == 16
    assert not result["collided"] and not result["off_road"] and result["simulated_s"] == 8.0
    assert result["distance_m"] > result["human_distance_m"]      # the faster lanes to the right

    world = CommonRoadWorld(traffic, 475)
    drive_world(world, RecordedRouteIdmPlanner(traffic, 475), LoopConfig(world.n_steps, 5), DriveHooks())
    _, lateral = _along(_lane(traffic, 2, 4), world.driven()[1][:, :2])
    assert lateral[-1] < -3.0                                     # it left lane 2 to the right
    assert np.diff(lateral).max() < 0.05                          # and never swerved back


def _fake_network(lanelets: dict[int, dict]):
    made = {i: SimpleNamespace(lanelet_id=i, successor=v.get("succ", []), predecessor=v.get("pred", []),
                               adj_left=v.get("left"), adj_left_same_direction=v.get("left") is not None,
                               adj_right=v.get("right"), adj_right_same_direction=v.get("right") is not None)
            for i, v in lanelets.items()}
    return SimpleNamespace(find_lanelet_by_id=made.__getitem__), made


def test_the_route_takes_the_recorded_branch_and_mobil_stays_off_diverging_lanes():
    # Two main-line lanes 1|2 going on to 4|5; lanelet 3 right of 2 is a ramp that leaves (to 6).
    network, ll = _fake_network({
        1: {"succ": [4], "right": 2}, 2: {"succ": [5, 3], "left": 1, "right": 3},
        3: {"succ": [6], "left": 2}, 4: {"pred": [1], "right": 5}, 5: {"pred": [2], "left": 4},
        6: {"pred": [3]}})
    assert LaneRoute(network, (1, 2, 5)).next(ll[2]).lanelet_id == 5
    assert LaneRoute(network, (2, 3)).next(ll[2]).lanelet_id == 3       # the recorded branch
    assert LaneRoute(network, (1,)).next(ll[2]).lanelet_id == 3         # else the lowest id
    freeway = LaneRoute(network, (1, 4))
    assert freeway.may_change_to(ll[1], ll[2])          # 2 goes on beside 1 (as 5 beside 4)
    assert not freeway.may_change_to(ll[2], ll[3])      # the ramp diverges
    assert LaneRoute(network, (2, 3, 6)).may_change_to(ll[2], ll[3])   # unless the human took it
    assert freeway.reachable(ll[2]) == {2, 3, 5, 6}


def test_the_route_is_the_recorded_vehicles_lanelets(traffic):
    assert recorded_lanelets(traffic, traffic.index_of(442)) == (2, 4)
    assert recorded_lanelets(traffic, traffic.index_of(389)) == (12, 15, 16)   # onto the ramp lane
