"""Attack scene records: the 2 Hz window at t0 cut from the human's 10 Hz log."""

import numpy as np
import pytest

from adversary.crash.scenes import AttackScene, load_record, record_attack_scene, save_record
from rasterize.errors import InputError


@pytest.fixture(scope="module")
def highway():
    return record_attack_scene(AttackScene("highway-v0", 0, 9))


def _check_window(record, radius_m: float, max_agents: int) -> None:
    window, log = record.window, record.log
    n = len(record.agent_ids)
    assert window.states.shape == (n, 17, 6) and window.current_index == 4 and window.dt == 0.5
    assert 2 <= n <= max_agents and record.agent_ids[0] == log.ego_id
    assert log.num_steps == 81                      # (t0 + horizon) * 10 Hz + 1
    k0 = 20
    for row, agent in enumerate(record.agent_ids):  # the window is the log at a 5-step stride
        times = k0 + 5 * np.arange(-4, 13)
        inside = times < log.num_steps
        np.testing.assert_array_equal(window.states[row, inside], log.states[agent, times[inside]])
    dist = np.linalg.norm(window.states[1:, 4, :2] - window.states[0, 4, :2], axis=1)
    assert np.all(np.diff(dist) >= 0) and dist.max() <= radius_m
    assert len(window.lanes) > 0


def test_highway_window_is_the_log_around_t0(highway):
    _check_window(highway, 60.0, 12)


def test_intersection_window_is_the_log_around_t0():
    record = record_attack_scene(AttackScene("intersection-v0", 0, 0), max_agents=4)
    _check_window(record, 60.0, 4)
    assert len(record.agent_ids) == 4


def test_save_and_load_are_bit_identical(highway, tmp_path):
    save_record(highway, tmp_path / "scene.npz")
    loaded = load_record(tmp_path / "scene.npz")
    assert loaded.scene == highway.scene
    np.testing.assert_array_equal(loaded.agent_ids, highway.agent_ids)
    np.testing.assert_array_equal(loaded.log.states, highway.log.states)
    np.testing.assert_array_equal(loaded.window.states, highway.window.states)
    np.testing.assert_array_equal(loaded.window.valid, highway.window.valid)
    np.testing.assert_array_equal(loaded.window.route_xy, highway.window.route_xy)
    assert len(loaded.window.lanes) == len(highway.window.lanes)
    for a, b in zip(loaded.window.lanes, highway.window.lanes):
        np.testing.assert_array_equal(a.left, b.left)
        assert (a.left_line, a.right_line, a.width_m) == (b.left_line, b.right_line, b.width_m)


def test_unreadable_record_is_an_input_error(tmp_path):
    (tmp_path / "bad.npz").write_bytes(b"not a record")
    with pytest.raises(InputError, match="unreadable"):
        load_record(tmp_path / "bad.npz")


@pytest.mark.parametrize("scene, message", [
    (AttackScene("nowhere-v0", 0, 0), "unknown env"),
    (AttackScene("highway-v0", 0, 0, t0_s=1.5), "history"),
    (AttackScene("highway-v0", 0, 0, horizon_s=5.3), "multiple"),
])
def test_bad_scenes_are_input_errors(scene, message):
    with pytest.raises(InputError, match=message):
        record_attack_scene(scene)


def test_a_scene_without_neighbours_is_an_input_error(highway):
    with pytest.raises(InputError, match="no other vehicle"):
        record_attack_scene(highway.scene, radius_m=1.0)



def test_a_human_that_crashes_before_the_horizon_ends_is_an_input_error():
    # intersection-v0 seed 0 episode 3: the human crashes at 6 s.
    with pytest.raises(InputError, match="crashed"):
        record_attack_scene(AttackScene("intersection-v0", 0, 3))
