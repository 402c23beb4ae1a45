"""Templates: the neutral vector is the base scene, perception degradation, the scripted target."""

import numpy as np
import pytest

from adversary.search.evaluation import EvaluationConfig, run_scenario
from adversary.search.scenarios import SCENE_RADIUS_M, TEMPLATES, Scenario, get_template
from rasterize.errors import InputError
from rasterize.frames import world_from_highway_env


def _env():
    from riskmap.sim.worlds.episode import make_env

    env = make_env("highway-v0", 10)
    env.unwrapped.config["vehicles_count"] = 0
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("name", sorted(TEMPLATES))
def test_neutral_vector_places_the_base_scene(name):
    t = get_template(name)
    env = _env()
    scenario = Scenario(t, t.as_dict(t.neutral), seed=0, dt_s=0.1)
    scenario.setup(env.unwrapped)
    road = env.unwrapped.road
    ego, target = road.vehicles
    b = t.base
    assert env.unwrapped.vehicle is ego
    gap = dict(zip(t.names, t.neutral))["gap_m"]
    # Lanes are 4 m wide, lane k centred at y = 4k in highway-env's frame.
    np.testing.assert_allclose(ego.position, [b.ego_s_m, 4.0 * b.ego_lane], atol=1e-12)
    np.testing.assert_allclose(target.position, [b.ego_s_m + gap + 5.0,
                                                 4.0 * (b.ego_lane + b.target_lane_offset)], atol=1e-12)
    assert ego.speed == target.speed == b.ego_speed_mps
    assert ego.heading == target.heading == 0.0


def test_neutral_vector_reproduces_the_base_scene_in_closed_loop():
    """Driving the neutral vector (perception hook active) equals driving the base scene
    (no perception hook at all), step for step."""
    from riskmap.registry import make_planner
    from riskmap.sim.loop.rollout import DriveHooks
    from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

    t = get_template("cut_in")
    config = EvaluationConfig("cv", "cut_in", episode_s=6.0)
    _, hooked = run_scenario(t, t.neutral, config)
    env = _env()
    base = Scenario(t, t.as_dict(t.neutral), 0, 0.1)
    positions = []
    hooks = DriveHooks(setup=base.setup, on_step=lambda run: positions.append(
        (world_from_highway_env(run.ego.position.copy()),
         world_from_highway_env(base.target.position.copy()))))
    drive_episode(env, make_planner("cv"), DriveConfig("highway-v0", 1, 0, 10, 2, 6.0), 0, hooks)
    ego_xy, target_xy = hooked.arrays()
    np.testing.assert_array_equal(ego_xy[1:], np.array([p[0] for p in positions]))
    np.testing.assert_array_equal(target_xy[1:], np.array([p[1] for p in positions]))


def _recorded_scene(scenario=None, steps: int = 24):
    from rasterize.highway import TrafficRecorder

    t = get_template("lead_brakes")
    env = _env()
    (scenario or Scenario(t, t.as_dict(t.neutral), 0, 0.1)).setup(env.unwrapped)
    road = env.unwrapped.road
    recorder = TrafficRecorder(road, env.unwrapped.vehicle, 0.1)
    recorder.record()
    for _ in range(steps):    # the env ends at the last recorded state, as in the drive loop
        road.act()
        road.step(0.1)
        recorder.record()
    return recorder.scene(recorder.num_steps - 1, 2.0, 0.0)


def _with(name, **changes):
    t = get_template(name)
    p = t.as_dict(t.neutral)
    p.update(changes)
    return Scenario(t, p, seed=3, dt_s=0.1)


def test_perception_degradation():
    scene = _recorded_scene()
    assert _with("lead_brakes").perceive(scene, 0) is scene          # neutral: untouched
    ego, other = scene.ego_index, 1 - scene.ego_index
    # Latency: the other agent appears 2 scene steps (1 s) late, the ego does not.
    late = _with("lead_brakes", latency_steps=2.0).perceive(scene, 0)
    np.testing.assert_array_equal(late.states[other, 2:], scene.states[other, :-2])
    assert not late.valid[other, :2].any()
    np.testing.assert_array_equal(late.states[ego], scene.states[ego])
    # Sensing range shorter than the 45 m centre distance: the other agent is gone.
    blind = _with("lead_brakes", sensing_range_m=30.0).perceive(scene, 0)
    assert not blind.valid[other].any()
    np.testing.assert_array_equal(blind.valid[ego], scene.valid[ego])
    assert _with("lead_brakes", sensing_range_m=60.0).perceive(scene, 0).valid[other].any()
    # Noise moves only the others, with the requested spread, and is seeded.
    noisy = _with("lead_brakes", position_noise_m=2.0, heading_noise_rad=0.3).perceive(scene, 7)
    again = _with("lead_brakes", position_noise_m=2.0, heading_noise_rad=0.3).perceive(scene, 7)
    np.testing.assert_array_equal(noisy.states, again.states)
    np.testing.assert_array_equal(noisy.states[ego], scene.states[ego])
    moved = noisy.states[other, :, :2] - scene.states[other, :, :2]
    assert 0.8 < moved.std() < 3.5
    np.testing.assert_allclose(np.hypot(noisy.states[other, :, 2], noisy.states[other, :, 3]), 1.0)
    # Drop probability 1 removes every other agent.
    assert not _with("lead_brakes", drop_probability=1.0 - 1e-12).perceive(scene, 0).valid[other].any()
    assert SCENE_RADIUS_M == get_template("cut_in").neutral[3]


def test_lead_brakes_at_the_scripted_rate():
    t = get_template("lead_brakes")
    env = _env()
    scenario = _with("lead_brakes", manoeuvre_time_s=1.0, brake_mps2=4.0)
    scenario.setup(env.unwrapped)
    target = scenario.target
    speeds = []
    for _ in range(40):
        target.act()
        target.step(0.1)
        speeds.append(target.speed)
    # Constant speed for 1 s, then −4 m/s² per second: 25 → 17 m/s two seconds later.
    assert speeds[9] == pytest.approx(25.0, abs=1e-9)
    assert speeds[29] == pytest.approx(25.0 - 4.0 * 2.0, abs=1e-6)
    assert t.target_speeds(scenario.params) == (25.0, 0.0)


def test_wrong_vector_length_is_a_clear_error():
    with pytest.raises(InputError, match="takes 10 parameters"):
        get_template("cut_in").as_dict(np.zeros(3))
    with pytest.raises(InputError, match="unknown template"):
        get_template("roundabout_merge")


def test_goal_is_recomputed_from_what_is_perceived():
    """The route rule caps the goal behind the leader; a leader the ego cannot see (out of
    sensing range) no longer caps it, and with everything seen the recomputed goal is the
    recorded one."""
    sees_all = _with("lead_brakes", sensing_range_m=119.0)
    scene = _recorded_scene(sees_all, steps=0)   # at the start: the leader 40 m ahead in lane
    seen = sees_all.perceive(scene, 0)
    np.testing.assert_allclose(seen.route_xy, scene.route_xy, atol=1e-9)
    blind = _with("lead_brakes", sensing_range_m=30.0)
    blind.env = sees_all.env
    unseen = blind.perceive(scene, 0)
    capped = np.linalg.norm(scene.route_xy[-1] - scene.route_xy[0])
    free = np.linalg.norm(unseen.route_xy[-1] - unseen.route_xy[0])
    # Free road: 6 s at the ego's speed gaining 1 m/s², at most the 30 m/s limit for 6 s.
    v = float(scene.ego_state()[4])
    assert free == pytest.approx(min(30.0 * 6.0, v * 6.0 + 0.5 * 1.0 * 36.0), abs=1e-4)  # chord
    assert capped < free - 20.0
