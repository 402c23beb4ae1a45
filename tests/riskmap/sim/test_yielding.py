"""The yielding teacher: gap acceptance at conflict zones, in highway-env's intersection."""

import numpy as np
import pytest

from riskmap.registry import make_planner
from riskmap.sim.drivers.yielding import GapAcceptance, _time_to_cover, conflict_stop_distance
from riskmap.sim.loop.rollout import DriveHooks, LoopConfig, drive_world
from riskmap.sim.worlds.episode import Episode, cached_env


def test_time_to_cover_matches_kinematics():
    # From standstill at 2 m/s² to 10 m/s: 25 m take 5 s; 45 m take 5 s + 20 m at 10 m/s.
    assert _time_to_cover(25.0, 0.0, 2.0, 10.0) == pytest.approx(5.0)
    assert _time_to_cover(45.0, 0.0, 2.0, 10.0) == pytest.approx(7.0)
    assert _time_to_cover(-1.0, 5.0, 2.0, 10.0) == 0.0


def _crossing(env, ego_s: float, other_s: float, other_speed: float):
    """The intersection road with only the ego (south arm, going straight north) and one car on
    the east arm going straight west, `ego_s`/`other_s` metres along their approach lanes."""
    from highway_env.vehicle.behavior import IDMVehicle

    env.reset(seed=0)
    road = env.unwrapped.road
    ego = IDMVehicle.make_on_lane(road, ("o0", "ir0", 0), longitudinal=ego_s, speed=8.0)
    ego.plan_route_to("o2")
    other = IDMVehicle.make_on_lane(road, ("o3", "ir3", 0), longitudinal=other_s, speed=other_speed)
    other.plan_route_to("o1")
    road.vehicles = [ego, other]
    return ego, other, road


def test_gives_way_to_a_car_arriving_together_and_goes_when_the_gap_is_large():
    env = cached_env("intersection-v0", 10)
    params = GapAcceptance()
    ego, _, road = _crossing(env, ego_s=80.0, other_s=80.0, other_speed=8.0)
    stop = conflict_stop_distance(ego, road.vehicles, params, 1.5, {})
    assert stop is not None and 5.0 < stop < 30.0   # waits before the crossing, not in it
    ego, _, road = _crossing(env, ego_s=80.0, other_s=10.0, other_speed=8.0)   # 70 m farther
    assert conflict_stop_distance(ego, road.vehicles, params, 1.5, {}) is None
    ego, _, road = _crossing(env, ego_s=80.0, other_s=80.0, other_speed=0.0)   # it waits
    assert conflict_stop_distance(ego, road.vehicles, params, 1.5, {}) is None


def test_teacher_avoids_the_crash_plain_idm_drives_into():
    # Seed 0, episode 3: highway-env's IDM ego collides with crossing traffic.
    env = cached_env("intersection-v0", 10)
    results = {}
    for spec in ("idm", "yielding"):
        run = Episode(env, "intersection-v0", 0, 3, 10)
        drive_world(run, make_planner(spec), LoopConfig(160, 1))
        results[spec] = (run.crashed, run.recorder.num_steps)
    assert results["idm"][0] and not results["yielding"][0]
    assert "critical_gap_s" in run.driver and 1.0 <= run.driver["critical_gap_s"] <= 2.0


def test_teacher_never_reverses():
    env = cached_env("intersection-v0", 10)
    run = Episode(env, "intersection-v0", 0, 35, 10)
    speeds = []
    drive_world(run, make_planner("yielding"), LoopConfig(160, 1),
                DriveHooks(on_step=lambda w: speeds.append(w.ego.speed)))
    assert min(speeds) >= 0.0 and not run.crashed
    assert np.mean(speeds) > 1.0   # it does drive


def test_yield_events_count_waits_for_crossing_traffic_only():
    from rasterize.scene import Scene
    from riskmap.sim.records.yield_events import YieldEventCounter

    def scene(other_xy, other_heading, other_speed=8.0):
        states = np.zeros((2, 1, 6))
        states[0, 0] = [0, 0, 1, 0, 0, 0]                       # ego at the origin facing +x
        states[1, 0] = [*other_xy, *other_heading, other_speed, 0]
        return Scene(states, np.ones((2, 1), bool), np.array([[5.0, 2.0]] * 2),
                     np.zeros(2, np.int8), 0, 0, 0.1)

    def count(frames, speed=0.0):
        counter = YieldEventCounter(0.1)
        for frame in frames:
            counter.update(speed, lambda f=frame: f)
        counter.update(5.0, None)                                # drives off: the wait ends
        return counter.events

    crossing = [scene((10.0, y), (0.0, 1.0)) for y in np.linspace(-6, 6, 15)]
    assert count(crossing) == 1
    assert count(crossing[:5]) == 0                              # 0.5 s: too short a wait
    assert count(crossing, speed=3.0) == 0                       # the ego did not wait
    queue = [scene((8.0, 0.0), (1.0, 0.0), 0.0)] * 15            # a stopped car ahead
    assert count(queue) == 0
    behind = [scene((-10.0, y), (0.0, 1.0)) for y in np.linspace(-6, 6, 15)]
    assert count(behind) == 0
