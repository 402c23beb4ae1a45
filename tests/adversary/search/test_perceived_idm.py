"""The IDM/MOBIL ego decides on degraded "ghost" vehicles when perception is degraded."""

import numpy as np

from adversary.search.evaluation import EvaluationConfig, evaluate
from adversary.search.scenarios import Scenario, get_template


def _setup(**changes):
    from riskmap.sim.worlds.episode import make_env

    t = get_template("lead_brakes")
    p = t.as_dict(t.neutral)
    p.update(changes)
    env = make_env("highway-v0", 10)
    env.unwrapped.config["vehicles_count"] = 0
    env.reset(seed=0)
    scenario = Scenario(t, p, seed=1, dt_s=0.1)
    scenario.setup(env.unwrapped)
    return env.unwrapped.road, env.unwrapped.vehicle, scenario.target


def _run(road, steps):
    for _ in range(steps):
        road.act()
        road.step(0.1)


def test_neutral_perception_keeps_the_plain_idm_ego():
    from highway_env.vehicle.behavior import IDMVehicle

    _, ego, _ = _setup()
    assert type(ego) is IDMVehicle


def test_ghosts_are_late_out_of_range_or_dropped():
    road, ego, target = _setup(latency_steps=2.0)          # 2 frames of 0.5 s = 10 control steps
    positions = []
    for _ in range(15):
        positions.append(target.position.copy())
        road.act()
        road.step(0.1)
    (ghost,) = ego._ghosts([target])
    # History holds the 15 positions seen at each act; the ghost is 10 steps behind the newest.
    np.testing.assert_array_equal(ghost.position, positions[-1 - 10])
    assert ghost is not target and ghost.speed == 25.0
    road, ego, target = _setup(sensing_range_m=30.0)        # target 45 m ahead: not seen
    _run(road, 1)
    assert ego._ghosts([target]) == []
    road, ego, target = _setup(sensing_range_m=50.0)
    _run(road, 1)
    assert len(ego._ghosts([target])) == 1
    road, ego, target = _setup(drop_probability=1.0 - 1e-12)
    _run(road, 1)
    assert ego._ghosts([target]) == []


def test_latency_makes_the_idm_ego_hit_a_hard_braking_lead():
    t = get_template("lead_brakes")
    config = EvaluationConfig("idm", "lead_brakes", episode_s=8.0)
    results = []
    for latency in (0.0, 2.0):
        p = t.as_dict(t.neutral)
        p.update(gap_m=15.0, brake_mps2=8.0, manoeuvre_time_s=2.0, latency_steps=latency)
        record = evaluate(t, np.array([p[n] for n in t.names]), config)
        assert record["feasible"]          # the scene is solvable with zero reaction time
        results.append(record["collided"])
    assert results == [False, True]
