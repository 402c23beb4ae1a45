"""Log-replay closed loop on a CommonRoad recording (highway-env road from the lanelets)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("commonroad")

from rasterize.commonroad import RecordedTraffic, load_scenario
from rasterize.errors import InputError
from rasterize.frames import world_from_highway_env
from riskmap.planner.baselines import ConstantVelocityPlanner
from riskmap.sim.loop.plan import Plan
from riskmap.sim.loop.rollout import DriveHooks, LoopConfig, drive_world
from riskmap.sim.worlds.commonroad_replay import (
    CommonRoadWorld,
    RecordedFuturePlanner,
    ReplayConfig,
    replay_commonroad_episode,
    road_from_lanelets,
)

RECORDING = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad" / "USA_US101-4_1_T-1.xml"


@pytest.fixture(scope="module")
def traffic() -> RecordedTraffic:
    return RecordedTraffic(load_scenario(RECORDING), RECORDING.stem)


def test_highway_env_road_has_the_lanelets_geometry(traffic):
    road = road_from_lanelets(traffic.scenario.lanelet_network)
    lanes = road.network.lanes_list()
    assert len(lanes) == len(traffic.scenario.lanelet_network.lanelets)
    # Every lanelet's centre points lie on the centre (lateral 0) of one highway-env lane.
    for lanelet in traffic.scenario.lanelet_network.lanelets:
        mid = lanelet.center_vertices[len(lanelet.center_vertices) // 2]
        hw = np.array([mid[0], -mid[1]])
        best = min(abs(lane.local_coordinates(hw)[1]) for lane in lanes if lane.on_lane(hw))
        assert best < 0.05
    # A recorded vehicle is on the road; a point 30 m beside the outer lanes is not.
    car = traffic.states[traffic.index_of(475), 50, :2]
    hw_car = np.array([car[0], -car[1]])
    assert any(lane.on_lane(hw_car) for lane in lanes)
    hx, hy = traffic.states[traffic.index_of(475), 50, 2:4]
    far = car + 30.0 * np.array([-hy, hx])          # 30 m to its left: 475 drives the left lane
    assert not any(lane.on_lane(np.array([far[0], -far[1]])) for lane in lanes)
    assert np.allclose(world_from_highway_env(hw_car), car)


def test_replaying_the_log_recovers_the_recorded_human(traffic):
    result = replay_commonroad_episode(traffic, 475, RecordedFuturePlanner(traffic, 475))
    assert result["simulated_s"] == pytest.approx(8.0)            # 2 s to the end of the record
    assert not result["collided"] and not result["off_road"]
    assert result["plan_calls"] == 16                              # 2 Hz over 8 s
    assert result["ade_m"] < 2.0 and result["goal_error_m"] < 3.0
    assert result["distance_m"] == pytest.approx(result["human_distance_m"], rel=0.15)
    assert result["min_gap_m"] > 1.0


def _who(result: dict) -> dict:
    """Whom the ego hit and whether it was ahead (the collision record without its class)."""
    return {k: result["collision"][k] for k in ("other_id", "other_ahead")}


def test_a_planner_that_ignores_the_slowing_leader_collides(traffic):
    # Vehicle 475 slows from 6 to 3 m/s behind a leader; holding 6 m/s runs into it.
    result = replay_commonroad_episode(traffic, 475, ConstantVelocityPlanner())
    assert result["collided"] and result["min_gap_m"] == 0.0
    assert _who(result) == {"other_id": 468, "other_ahead": True}
    assert result["collision"]["failure"]["fault"] == "at fault"          # classified (riskmap.sim.records.failures)
    assert result["collision"]["failure"]["avoidable"]                    # braking for the leader would do
    assert result["simulated_s"] < 8.0
    assert result["ade_m"] > 1.0


def test_the_rollout_loop_drives_a_commonroad_world(traffic):
    # The loop shared with highway-env episodes: the recorded future, tracked from wherever the
    # ego is, stays close to the human all the way to the end of the recording.
    world = CommonRoadWorld(traffic, 475)
    steps = []
    loop = drive_world(world, RecordedFuturePlanner(traffic, 475), LoopConfig(world.n_steps, 5),
                       DriveHooks(on_step=lambda w: steps.append(w.steps)))
    assert world.done and not world.crashed and not world.off_network
    assert steps == list(range(1, world.n_steps + 1)) and world.n_steps == 80
    assert len(loop.plan_times_s) == 16 and not loop.drives_itself
    t, driven = world.driven()
    assert np.allclose(t, world.start + world.dt * np.arange(1, 81))
    human, _ = traffic.resample(np.array([world.ego_index]), t)
    errors = np.linalg.norm(driven[:, :2] - human[0, :, :2], axis=1)
    assert errors.mean() < 2.0 and errors.max() < 3.0
    assert loop.distance_m == pytest.approx(np.linalg.norm(np.diff(
        np.asarray(world.track)[world.history_len - 1:, :2], axis=0), axis=1).sum())
    assert min(loop.gaps) == pytest.approx(replay_commonroad_episode(
        traffic, 475, RecordedFuturePlanner(traffic, 475))["min_gap_m"])


class _StopPlanner:
    def reset(self, scene) -> None:
        pass

    def plan(self, scene) -> Plan:
        return Plan(np.zeros((12, 2)))


def test_replayed_traffic_does_not_react_and_the_report_says_so(traffic):
    # 468 is 475's leader: stopping it gets it struck from behind by the replayed 475.
    result = replay_commonroad_episode(traffic, 468, _StopPlanner())
    assert result["collided"] and _who(result) == {"other_id": 475, "other_ahead": False}
    assert result["collision"]["failure"]["fault"] == "struck from behind"
    assert result["distance_m"] < 0.25 * result["human_distance_m"]      # it braked to a stop


def test_bad_input_is_an_input_error(traffic):
    with pytest.raises(InputError, match="ego id 1"):
        replay_commonroad_episode(traffic, 1, ConstantVelocityPlanner())
    with pytest.raises(InputError, match="outside vehicle 475"):
        replay_commonroad_episode(traffic, 475, ConstantVelocityPlanner(), start_s=12.0)
    with pytest.raises(InputError, match="does not exist"):
        replay_commonroad_episode(RECORDING.with_name("none.xml"), 475, ConstantVelocityPlanner())


def test_the_human_goal_is_where_the_recorded_vehicle_is_at_the_horizon(traffic):
    from rasterize.config import FAMILY_EXTENTS, GridConfig
    from rasterize.frames import ego_from_grid, ego_from_world, ego_pose
    from rasterize.maps import route_goal_cell
    from riskmap.sim.worlds.commonroad_replay import ReplayConfig

    vehicle = 475
    agent = traffic.index_of(vehicle)
    world = CommonRoadWorld(traffic, vehicle, config=ReplayConfig(goal="human"))
    scene = world.scene(2.0)
    grid = GridConfig(FAMILY_EXTENTS["highway"], 50, 50)
    there, _ = traffic.resample(np.array([agent]), np.array([world.time_s + 6.0]))   # inside the record
    end_ego = ego_from_world(there[0, :, :2], *ego_pose(scene))[0]
    route_ego = ego_from_world(scene.route_xy, *ego_pose(scene))
    # the route runs straight from the ego to where the human is 6 s from now
    np.testing.assert_allclose(route_ego[0], [0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(route_ego[-1], end_ego, atol=1e-9)
    # inside the grid, the planner's goal cell is the one holding that position
    goal = ego_from_grid(route_goal_cell(scene, grid), grid)
    assert abs(goal[0] - end_ego[0]) <= 240.0 / 50 and abs(goal[1] - end_ego[1]) <= 40.0 / 50
    route = CommonRoadWorld(traffic, vehicle).scene(2.0)
    assert not np.allclose(route.route_xy[-1], scene.route_xy[-1])   # the route rule's goal differs
    # Near the end of the record the human is extrapolated at its last speed and heading.
    first, last = traffic.span(agent)
    late = CommonRoadWorld(traffic, vehicle, start_s=last * traffic.dt_s - 1.0,
                           config=ReplayConfig(goal="human"))
    final = traffic.states[agent, last]
    expected = final[:2] + 5.0 * final[4] * final[2:4]
    np.testing.assert_allclose(late.scene(2.0).route_xy[-1], expected, atol=1e-6)
    with pytest.raises(InputError, match="--goal 'nope'"):
        ReplayConfig(goal="nope")


class _HumanEgoWorld(CommonRoadWorld):
    """The ego is put exactly where the recorded human was at every step."""

    def _move_ego(self) -> np.ndarray:
        state, _ = self.traffic.resample(np.array([self.ego_index]), np.array([self.time_s + self.dt]))
        return state[0, 0]


@pytest.mark.parametrize("vehicle", [442, 468, 475])
def test_reactive_traffic_reproduces_the_recording_when_the_ego_is_the_human(traffic, vehicle):
    # 442 and 468 have followers closer than IDM's desired gap in the recording: they must not
    # brake for an ego that is where the human was.
    world = _HumanEgoWorld(traffic, vehicle, config=ReplayConfig(mode="reactive"))
    times = [world.time_s]
    for _ in range(world.n_steps):
        world.step()
        times.append(world.time_s)
    assert not world.crashed
    times = np.array(times)
    reactive, present = world.others_at(world.others, times)
    recorded, recorded_present = traffic.resample(world.others, times)
    assert present.any() and (present == recorded_present).all()
    np.testing.assert_allclose(reactive[present][:, :2], recorded[present][:, :2], rtol=0, atol=1e-6)
    # The planner's scene (history included) holds the recorded others too.
    scene = world.scene(2.0)
    log_scene = CommonRoadWorld(traffic, vehicle)
    log_scene.track_t, log_scene.track, log_scene.steps = world.track_t, world.track, world.steps
    np.testing.assert_allclose(scene.states, log_scene.scene(2.0).states, rtol=0, atol=1e-6)


@pytest.mark.parametrize("planner", ["cv", "replay"])
def test_reactive_traffic_with_a_planner_that_keeps_up_behaves_as_the_log(traffic, planner):
    for vehicle in (475, 468):
        make = lambda: (ConstantVelocityPlanner() if planner == "cv"  # noqa: E731
                        else RecordedFuturePlanner(traffic, vehicle))
        log = replay_commonroad_episode(traffic, vehicle, make())
        reactive = replay_commonroad_episode(traffic, vehicle, make(),
                                             config=ReplayConfig(mode="reactive"))
        for key in ("collided", "min_gap_m", "ade_m", "safety_pct", "simulated_s"):
            assert reactive[key] == pytest.approx(log[key]), key
        assert reactive["collision"] == log["collision"]


def test_reactive_traffic_brakes_for_a_stopped_ego(traffic):
    # In log mode the replayed 475 runs into 468 stopped ahead of it; reactive, it stops behind.
    log = replay_commonroad_episode(traffic, 468, _StopPlanner())
    assert _who(log) == {"other_id": 475, "other_ahead": False}
    world = CommonRoadWorld(traffic, 468, config=ReplayConfig(mode="reactive"))
    loop = drive_world(world, _StopPlanner(), LoopConfig(world.n_steps, 5))
    assert not world.crashed and world.collision is None and world.steps == world.n_steps
    assert min(loop.gaps) >= 0.0
    follower = np.array([traffic.index_of(475)])
    driven, recorded = world.others_at(follower, np.array([world.time_s]))[0], traffic.resample(
        follower, np.array([world.time_s]))[0]
    assert np.linalg.norm(driven[0, 0, :2] - recorded[0, 0, :2]) > 5.0   # it fell behind its log
    assert driven[0, 0, 4] < 0.5 and world.ego.speed < 0.5              # both came to a stop
    result = replay_commonroad_episode(traffic, 468, _StopPlanner(), config=ReplayConfig(mode="reactive"))
    assert not result["collided"] and result["min_gap_m"] >= 0.0


def test_an_unknown_mode_is_an_input_error():
    with pytest.raises(InputError, match="--mode 'x'"):
        ReplayConfig(mode="x")
