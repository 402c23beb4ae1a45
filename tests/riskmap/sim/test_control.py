import gymnasium as gym
import highway_env  # noqa: F401
import numpy as np
import pytest

from riskmap.sim.loop.control import TrackingController, planned_vehicle_class


def test_straight_plan_gives_straight_steering_and_the_plan_speed():
    ctrl = TrackingController()
    waypoints = np.stack([np.arange(1, 13) * 5.0, np.zeros(12)], axis=1)   # 5 m per 0.5 s
    ctrl.set_plan(waypoints, np.array([100.0, 50.0]), 0.0)
    assert ctrl.target_speed(0.0) == pytest.approx(10.0)
    accel, steer = ctrl.action(np.array([100.0, 50.0]), 0.0, 10.0, 0.0, 0.1)
    assert steer == pytest.approx(0.0, abs=1e-9) and accel == pytest.approx(0.0, abs=1e-9)
    accel, _ = ctrl.action(np.array([100.0, 50.0]), 0.0, 5.0, 0.1, 0.1)
    assert accel > 0


def test_a_path_to_the_left_steers_left():
    ctrl = TrackingController()
    t = np.arange(1, 13)
    ctrl.set_plan(np.stack([t * 3.0, 0.05 * (t * 3.0) ** 2 / 10], axis=1), np.zeros(2), 0.0)
    _, steer = ctrl.action(np.zeros(2), 0.0, 6.0, 0.0, 0.1)
    assert steer > 0.0


def test_a_stay_put_plan_brakes_to_a_stop_without_reversing():
    ctrl = TrackingController()
    ctrl.set_plan(np.zeros((12, 2)), np.zeros(2), 0.0)
    accel, steer = ctrl.action(np.zeros(2), 0.0, 0.2, 0.0, 0.1)
    assert steer == 0.0 and -2.0 <= accel < 0.0          # -2 m/s² stops 0.2 m/s in one 0.1 s step
    ctrl.set_plan(np.zeros((12, 2)), np.zeros(2), 0.0)
    for _ in range(50):                                  # however long it waits at a standstill
        accel, _ = ctrl.action(np.zeros(2), 0.0, 0.0, 0.0, 0.1)
        assert accel >= 0.0


def test_tracking_a_lane_change_in_highway_env():
    """Closed form: 6 s at 20 m/s is 120 m; a 4 m lane change to the left is completed."""
    env = gym.make("highway-v0", config={"vehicles_count": 0, "simulation_frequency": 10})
    env.reset(seed=0)
    base = env.unwrapped
    old = base.vehicle
    ego = planned_vehicle_class()(base.road, old.position.copy(), 0.0, 20.0)
    base.road.vehicles[base.road.vehicles.index(old)] = ego
    start = np.array([ego.position[0], -ego.position[1]])               # toolkit frame
    x = np.arange(1, 13) * 10.0                                           # 20 m/s
    y = 4.0 / (1 + np.exp(-(x - 50.0) / 10.0))                           # smooth 4 m to the left
    ctrl = TrackingController()
    ctrl.set_plan(np.stack([x, y], axis=1), start, 0.0)
    for k in range(60):
        pos = np.array([ego.position[0], -ego.position[1]])
        accel, steer = ctrl.action(pos, -ego.heading, ego.speed, k * 0.1, 0.1)
        ego.command(accel, steer)
        base.road.act()
        base.road.step(0.1)
    end = np.array([ego.position[0], -ego.position[1]]) - start
    assert end[0] == pytest.approx(120.0, abs=3.0)
    assert end[1] == pytest.approx(4.0, abs=0.5)
    assert abs(ego.heading) < 0.05


def test_a_braking_plan_is_tracked_without_lag():
    """A plan to stop from 7 m/s within 7.35 m (constant -3.33 m/s²): the command follows the
    plan's deceleration at once, and driven by it the ego stops within a metre of the end."""
    v0, a = 7.0, -7.0 ** 2 / (2 * 7.35)
    t = 0.5 * np.arange(1, 13)
    s = np.where(t < v0 / -a, v0 * t + 0.5 * a * t ** 2, 7.35)
    ctrl = TrackingController()
    ctrl.set_plan(np.stack([s, np.zeros(12)], axis=1), np.zeros(2), 0.0)
    accel, _ = ctrl.action(np.zeros(2), 0.0, v0, 0.0, 0.1)
    assert accel == pytest.approx(a, abs=0.5)
    x, v = 0.0, v0
    for k in range(80):
        accel, _ = ctrl.action(np.array([x, 0.0]), 0.0, v, k * 0.1, 0.1)
        v = max(v + accel * 0.1, 0.0)
        x += v * 0.1
    assert v == pytest.approx(0.0, abs=0.05) and x == pytest.approx(7.35, abs=1.0)
