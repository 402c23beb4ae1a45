"""Static (parked / stopped) vehicles in attack scenes: placement, stillness, masking, replay."""

import json
from pathlib import Path

import numpy as np
import pytest

from adversary.crash.batch import collate
from adversary.crash.features import FeatureConfig, scene_tensors
from adversary.crash.judge import judge, rollout
from adversary.crash.scene_sweep import EnvSweep, record_scenes
from adversary.crash.scenes import AttackScene, load_record, record_attack_scene, save_record
from adversary.crash.selection import candidates
from rasterize.errors import InputError
from riskmap.registry import cached_planner
from riskmap.sim.drivers.static_agents import StaticPlacement, is_static
from riskmap.sim.records.metrics import min_box_gap, vehicle_box
from riskmap.sim.worlds.episode import Episode, cached_env, make_env
from riskmap.sim.worlds.log_replay import LogReplayEpisode, log_of

CHECKPOINTS = Path(__file__).resolve().parents[3] / "checkpoints"
# highway-v0 seed 500 episode 4: the three static cars stand in the ego's own lane, 97 m, 127 m
# and 140 m ahead at t = 0; the first of them is window row 3 at t0 (the human changes lanes).
HIGHWAY, IN_LANE_ROW = AttackScene("highway-v0", 500, 4, static_agents=3), 3
INTERSECTION = AttackScene("intersection-v0", 0, 2, static_agents=3)


def _static_ids(log, count: int) -> np.ndarray:
    """Log agents of the static cars: the reset appends them after the env's own vehicles."""
    return np.flatnonzero(log.valid[:, 0])[-count:]


@pytest.fixture(scope="module")
def highway():
    return record_attack_scene(HIGHWAY)


@pytest.fixture(scope="module")
def intersection():
    return record_attack_scene(INTERSECTION)


def _placed(env_id: str, seed: int, episode: int, count: int = 3):
    run = Episode(cached_env(env_id, 10), env_id, seed, episode, 10, static_agents=count)
    return run, [v for v in run.base.road.vehicles if is_static(v)]


@pytest.mark.parametrize("env_id, seed, episode", [("highway-v0", 500, 4), ("intersection-v0", 0, 2)])
def test_static_vehicles_stand_on_lane_centres_clear_of_everyone(env_id, seed, episode):
    run, static = _placed(env_id, seed, episode)
    road, config = run.base.road, StaticPlacement()
    assert len(static) == 3 and all(v.speed == 0.0 for v in static)
    for v in static:
        lane = road.network.get_lane(v.lane_index)
        s, lateral = lane.local_coordinates(v.position)
        assert abs(lateral) < 1e-9 and abs(lane.heading_at(s) - v.heading) < 1e-9
        traffic = [vehicle_box(o) for o in road.vehicles if not is_static(o)]
        assert min_box_gap(vehicle_box(v), traffic) >= config.clearance_m - 1e-9
        # A queue stands bumper to bumper; nowhere do static cars overlap.
        statics = [vehicle_box(o) for o in static if o is not v]
        assert min_box_gap(vehicle_box(v), statics) >= min(config.clearance_m, config.queue_gap_m[0]) - 1e-9
    # The recorder has them, as vehicles, from the first step.
    ids = [run.recorder.known_id(v) for v in static]
    assert None not in ids and all(run.recorder.latest_state(i)[4] == 0.0 for i in ids)


def test_the_intersection_queue_waits_bumper_to_bumper_on_another_approach():
    run, static = _placed("intersection-v0", 0, 2)
    lanes = {v.lane_index for v in static}
    assert len(lanes) == 1
    (lane_index,) = lanes
    assert lane_index[0].startswith("o") and lane_index[1].startswith("ir")
    assert lane_index[:2] != run.ego.lane_index[:2]
    lane = run.base.road.network.get_lane(lane_index)
    s = sorted(lane.local_coordinates(v.position)[0] for v in static)
    gaps = np.diff(s) - static[0].LENGTH
    assert np.all((gaps >= 1.5 - 1e-9) & (gaps <= 2.0 + 1e-9))
    front_gap = lane.length - s[-1] - 0.5 * static[0].LENGTH      # to the junction
    assert 0.5 - 1e-9 <= front_gap <= 2.0 + 1e-9


def test_same_seed_and_episode_same_places():
    first = [v.position.copy() for v in _placed("highway-v0", 500, 4)[1]]
    again = [v.position.copy() for v in _placed("highway-v0", 500, 4)[1]]
    other = [v.position.copy() for v in _placed("highway-v0", 500, 5)[1]]
    np.testing.assert_array_equal(first, again)
    assert not np.allclose(first, other)


@pytest.mark.parametrize("which", ["highway", "intersection"])
def test_static_vehicles_never_move_and_nobody_runs_into_them(which, request):
    record = request.getfixturevalue(which)
    log = record.log
    static = _static_ids(log, 3)
    for a in static:
        assert log.valid[a, : record.t0_step + 1].all()
        np.testing.assert_array_equal(log.states[a, log.valid[a], :2], np.broadcast_to(log.states[a, 0, :2], (log.valid[a].sum(), 2)))
        assert np.all(log.states[a, log.valid[a], 4] == 0.0)
    # Traffic treats them as obstacles: no box ever touches theirs.
    for k in range(log.num_steps):
        for a in static:
            others = [b for b in np.flatnonzero(log.valid[:, k]) if b != a]
            gap = min_box_gap(_box(log, a, k), (_box(log, b, k) for b in others))
            assert gap > 0.0, f"agent {a} touched at step {k}"


def _box(log, agent: int, step: int) -> np.ndarray:
    from rasterize.frames import box_corners

    state = log.states[agent, step]
    return box_corners(state[:2], state[2:4], *log.sizes[agent])


@pytest.mark.parametrize("which, family", [("highway", "highway"), ("intersection", "intersection")])
def test_motion_aware_masking_masks_them_and_no_masking_keeps_them(which, family, request):
    record = request.getfixturevalue(which)
    features = FeatureConfig(**json.loads((CHECKPOINTS / f"crash_traffic_{family}.json").read_text())["features"])
    item = scene_tensors(record.window, features)
    static = set(_static_ids(record.log, 3).tolist())
    is_static_row = np.array([int(record.agent_ids[r]) in static for r in item.rows])
    assert is_static_row.any()
    batch = collate([item])
    masked, kept = candidates(batch, mam=True)[0].numpy(), candidates(batch, mam=False)[0].numpy()
    assert not masked[is_static_row].any()
    assert kept[is_static_row].all()
    # Moving traffic stays a candidate either way.
    moving = ~is_static_row
    moving[0] = False
    assert np.array_equal(masked[moving], kept[moving])


def test_the_judge_rollout_has_them_where_the_record_has_them(highway):
    planner = cached_planner("idm")
    result = rollout(highway, np.zeros((0, highway.scene.future_steps, 6)), [], planner, "idm")
    for a in _static_ids(highway.log, 3):
        r = result.recorder_id(int(a))
        assert r >= 0 and result.valid[r, 0]
        np.testing.assert_array_equal(result.valid[r], highway.log.valid[a, : result.valid.shape[1]])
        np.testing.assert_array_equal(result.states[r, result.valid[r], :2],
                                      highway.log.states[a, : result.valid.shape[1]][result.valid[r], :2])


def test_a_planner_driving_into_a_static_car_is_a_measured_collision(highway):
    # Constant velocity keeps the ego's lane: it meets the first static car in it (~97 m ahead).
    planner = cached_planner("cv")
    verdict = judge(highway, np.zeros((0, highway.scene.future_steps, 6)), [], IN_LANE_ROW, planner, "cv")
    assert int(highway.agent_ids[IN_LANE_ROW]) in _static_ids(highway.log, 3)
    assert verdict["collision"] and verdict["collision_any"] and verdict["collision_any_row"] == IN_LANE_ROW


def test_zero_static_agents_is_the_episode_as_before():
    env = cached_env("highway-v0", 10)
    logs = []
    for keywords in ({}, {"static_agents": 0}):      # one at a time: they share the env
        run = Episode(env, "highway-v0", 500, 4, 10, **keywords)
        for _ in range(20):
            run.step()
        logs.append(log_of(run))
    for name in ("states", "valid", "sizes", "kinds"):
        np.testing.assert_array_equal(getattr(logs[0], name), getattr(logs[1], name))
    # Static cars come after the env's own vehicles and leave them as the reset made them.
    with_static = log_of(Episode(env, "highway-v0", 500, 4, 10, static_agents=3))
    n = logs[0].valid[:, 0].sum()
    np.testing.assert_array_equal(with_static.states[:n, 0], logs[0].states[:n, 0])


@pytest.mark.parametrize("env_id, seed, episode", [("highway-v0", 500, 4), ("intersection-v0", 0, 2)])
def test_the_fast_road_drives_static_cars_as_highway_env_does(env_id, seed, episode):
    logs = []
    for fast in (False, True):
        run = Episode(make_env(env_id, 10, fast=fast), env_id, seed, episode, 10, static_agents=3)
        for _ in range(40):
            run.step()
        logs.append(log_of(run))
    for name in ("states", "valid", "sizes", "kinds"):
        np.testing.assert_array_equal(getattr(logs[0], name), getattr(logs[1], name))


def test_a_replay_without_the_static_cars_of_its_log_is_refused(highway):
    env = cached_env("highway-v0", 10)
    with pytest.raises(InputError, match="static vehicles"):
        LogReplayEpisode(env, "highway-v0", 500, 4, highway.log, 10)
    LogReplayEpisode(env, "highway-v0", 500, 4, highway.log, 10, static_agents=3)


def test_saved_scene_keeps_its_static_cars(highway, tmp_path):
    save_record(highway, tmp_path / "scene.npz")
    loaded = load_record(tmp_path / "scene.npz")
    assert loaded.scene.static_agents == 3
    np.testing.assert_array_equal(loaded.window.states, highway.window.states)


@pytest.mark.parametrize("scene", [AttackScene("roundabout-v0", 0, 0, static_agents=1),
                                   AttackScene("highway-v0", 0, 0, static_agents=-1),
                                   AttackScene("highway-v0", 0, 0, static_agents=11)])
def test_bad_static_agents_are_input_errors(scene):
    with pytest.raises(InputError, match="static"):
        scene.check(10)


def test_scene_index_keeps_the_count_and_a_resume_with_another_is_refused(tmp_path):
    out = tmp_path / "scenes"
    index = record_scenes(EnvSweep("intersection-v0", 0, first_episode=2, static_agents=2), 1, out, progress=False)
    assert index["static_agents"] == 2 and index["scenes"] == ["scene_00002"]
    assert json.loads((out / "scene_00002.json").read_text())["static_agents"] == 2
    with pytest.raises(InputError, match="--static-agents 2"):
        record_scenes(EnvSweep("intersection-v0", 0, first_episode=2), 1, out, resume=True, progress=False)
