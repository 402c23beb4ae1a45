"""The highway-env adapter on every road-network family (straight, sine, circular, poly lanes)."""

import gymnasium as gym
import highway_env  # noqa: F401
import numpy as np
import pytest

from rasterize.config import raster_config_for_env
from rasterize.frames import ego_from_world, ego_pose
from rasterize.highway import TrafficRecorder, lanes_near, scene_from_highway_env
from rasterize.raster import CHANNEL_INDEX, rasterize_scene

ENVS = ["highway-v0", "merge-v0", "roundabout-v0", "intersection-v0"]


@pytest.fixture(scope="module", params=ENVS)
def env(request):
    env = gym.make(request.param)
    env.reset(seed=3)
    yield env
    env.close()


def test_scene_now_matches_the_simulator(env):
    base = env.unwrapped
    scene = scene_from_highway_env(env, history_s=2.0, future_s=0.0)
    ego = scene.ego_state()
    # highway-env's y points down the screen: ours points up.
    np.testing.assert_allclose(ego[:2], [base.vehicle.position[0], -base.vehicle.position[1]])
    assert ego[4] == pytest.approx(base.vehicle.speed)
    assert np.hypot(ego[2], ego[3]) == pytest.approx(1.0)
    # Without a recorder only the present is known.
    assert scene.valid[:, : scene.current_index].sum() == 0
    assert scene.num_agents >= 2 and len(scene.lanes) >= 2


def test_ego_sits_on_a_drivable_lane(env):
    scene = scene_from_highway_env(env)
    config = raster_config_for_env(env.unwrapped.spec.id)
    raster = rasterize_scene(scene, config)
    ego = raster[CHANNEL_INDEX["ego"]] > 0
    drivable = raster[CHANNEL_INDEX["drivable"]] > 0
    assert ego.sum() > 0 and (drivable & ego).sum() / ego.sum() > 0.95


def test_lane_boundaries_lie_left_and_right_of_the_driving_direction(env):
    scene = scene_from_highway_env(env)
    for lane in scene.lanes:
        tangent = lane.centre[-1] - lane.centre[0]
        if np.linalg.norm(tangent) < 1.0:
            continue
        mid = len(lane.centre) // 2
        to_left = lane.left[mid] - lane.centre[mid]
        cross = tangent[0] * to_left[1] - tangent[1] * to_left[0]
        assert cross > 0, "left boundary must be on the left (counter-clockwise) side"
        assert np.linalg.norm(to_left) == pytest.approx(lane.width_m / 2, rel=0.05)


def test_future_comes_from_a_copy_and_leaves_the_env_untouched(env):
    base = env.unwrapped
    before = [v.position.copy() for v in base.road.vehicles]
    scene = scene_from_highway_env(env, history_s=0.0, future_s=2.0, dt_s=0.5)
    after = [v.position for v in base.road.vehicles]
    for b, a in zip(before, after):
        np.testing.assert_array_equal(a, b)
    assert scene.num_future_steps == 4 and scene.valid[0].all()
    # The ego moves forward along its heading about speed x time.
    origin, heading = ego_pose(scene)
    travelled = ego_from_world(scene.ego_future_xy()[-1], origin, heading)
    assert travelled[0] == pytest.approx(scene.ego_state()[4] * 2.0, rel=0.35)


def test_recorder_history_is_resampled_and_kinematically_consistent():
    env = gym.make("highway-v0", config={"simulation_frequency": 10, "vehicles_count": 10})
    env.reset(seed=0)
    base = env.unwrapped
    recorder = TrafficRecorder(base.road, base.vehicle, dt_s=0.1)
    recorder.record()
    for _ in range(30):
        base.road.act()
        base.road.step(0.1)
        recorder.record()
    scene = scene_from_highway_env(env, history_s=2.0, recorder=recorder, dt_s=0.5)
    assert scene.current_index == 4 and scene.valid[0].all()
    # 2 s at ~speed m/s: the ego covered about speed x 2 m (closed-form check).
    ego = scene.states[0]
    distance = np.linalg.norm(ego[-1, :2] - ego[0, :2])
    assert distance == pytest.approx(ego[:, 4].mean() * 2.0, rel=0.05)


def test_lanes_near_crops_long_lanes():
    env = gym.make("highway-v0")
    env.reset(seed=0)
    from rasterize.highway import LaneSampling

    lanes = lanes_near(env.unwrapped.road.network, np.array([500.0, 0.0]), LaneSampling(radius_m=50))
    assert len(lanes) == 4
    for lane in lanes:
        assert lane.centre[:, 0].min() >= 449.0 and lane.centre[:, 0].max() <= 551.0
        assert lane.centre.shape[0] == 2      # straight lanes simplify to their two ends


def _lone_ego(speed):
    env = gym.make("highway-v0", config={"vehicles_count": 0, "simulation_frequency": 10})
    env.reset(seed=0)
    ego = env.unwrapped.vehicle
    ego.speed = speed
    return env, ego


def test_route_rule_free_road_hand_computed():
    from rasterize.highway import RouteRule, route_ahead

    env, ego = _lone_ego(20.0)
    route = route_ahead(env.unwrapped.road, ego, RouteRule())
    # min(30 m/s x 6 s, 20 x 6 + 1 x 36 / 2) = 138 m straight ahead along the lane.
    travelled = route[-1] - route[0]
    assert travelled[0] == pytest.approx(138.0, abs=1e-6) and abs(travelled[1]) < 1e-6
    assert len(route) == 13


def test_route_rule_stops_behind_a_leader_hand_computed():
    from highway_env.vehicle.kinematics import Vehicle

    from rasterize.highway import RouteRule, route_ahead

    env, ego = _lone_ego(20.0)
    road = env.unwrapped.road
    leader = Vehicle(road, ego.position + np.array([35.0, 0.0]), heading=0.0, speed=10.0)
    road.vehicles.append(leader)
    beside = Vehicle(road, ego.position + np.array([20.0, 4.0]), heading=0.0, speed=0.0)
    road.vehicles.append(beside)                   # next lane: does not cap
    route = route_ahead(road, ego, RouteRule())
    # bumper gap 30 m, leader covers 60 m in 6 s, keep 5 m + 10 m/s x 1.5 s: 30 + 60 - 20 = 70 m.
    assert (route[-1] - route[0])[0] == pytest.approx(70.0, abs=1.0)
