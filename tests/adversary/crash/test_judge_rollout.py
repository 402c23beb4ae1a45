"""Splicing generated futures into the log, closed-loop rollouts against them and their verdict."""

from dataclasses import replace

import numpy as np
import pytest

from adversary.crash.judge import (
    braking_track,
    cached_planner,
    ego_future_2hz,
    ego_track_2hz,
    judge,
    rollout,
    splice_tracks,
)
from adversary.crash.scenes import AttackScene, record_attack_scene
from rasterize.errors import InputError

# Episode 9 of highway-v0 seed 0: window row 3 drives ahead of the ego in the lane the ego keeps.
SCENE, AHEAD = AttackScene("highway-v0", 0, 9), 3


@pytest.fixture(scope="module")
def record():
    return record_attack_scene(SCENE)


def _wavy(record, row):
    """A track [12, 6] unlike any logged one: the row's t0 state, drifting and slowing."""
    state = record.window.states[row, 4]
    t = 0.5 * np.arange(1, 13)
    heading = np.radians(3.0) * np.sin(t)
    return np.column_stack([state[0] + 15.0 * t, state[1] + 0.5 * np.sin(t), np.cos(heading), np.sin(heading),
                            15.0 - 0.5 * t, np.zeros(12)])


def test_splice_puts_knots_exactly_and_keeps_everyone_else(record):
    rows = [1, AHEAD]
    tracks = np.stack([_wavy(record, row) for row in rows])
    spliced = splice_tracks(record, tracks, rows)
    log, k0 = record.log, 20
    assert spliced.num_steps == 81
    for row, track in zip(rows, tracks):
        agent = record.agent_ids[row]
        np.testing.assert_array_equal(spliced.states[agent, k0 + 5:81:5], track)
        np.testing.assert_array_equal(spliced.states[agent, :k0 + 1], log.states[agent, :k0 + 1])
        assert spliced.valid[agent, k0:].all()
        between = spliced.states[agent, k0:81, :2]           # no jumps between knots
        assert np.linalg.norm(np.diff(between, axis=0), axis=1).max() < 2.0
    spliced_agents = set(record.agent_ids[rows].tolist())
    for agent in range(len(log.states)):
        if agent not in spliced_agents:
            np.testing.assert_array_equal(spliced.states[agent], log.states[agent, :81])
            np.testing.assert_array_equal(spliced.valid[agent], log.valid[agent, :81])


def test_spliced_agent_whose_record_ended_stays_on_the_road(record):
    agent = record.agent_ids[AHEAD]
    valid = record.log.valid.copy()
    valid[agent, 30:] = False                             # its record ends 1 s after t0
    short = replace(record, log=replace(record.log, valid=valid))
    spliced = splice_tracks(short, _wavy(record, AHEAD)[None], [AHEAD])
    assert spliced.valid[agent, 20:].all()


@pytest.mark.parametrize("rows, shape", [([0], (1, 12, 6)), ([1, 1], (2, 12, 6)), ([1], (1, 11, 6)),
                                         ([99], (1, 12, 6))])
def test_bad_rows_or_tracks_are_input_errors(record, rows, shape):
    with pytest.raises(InputError):
        splice_tracks(record, np.zeros(shape), rows)


def test_car_ahead_braking_to_a_stop_is_rear_ended_by_the_replayed_human(record):
    planner = cached_planner("replay")
    tracks = braking_track(record, AHEAD, decel_mps2=8.0)[None]
    result = rollout(record, tracks, [AHEAD], planner, "replay")
    metrics = judge(record, tracks, [AHEAD], AHEAD, planner, "replay", result=result)
    assert metrics["collision"] and metrics["collision_iou"] > 0.02
    assert metrics["collision_type"] == "ego rear-ends"
    assert metrics["collision_any_row"] == AHEAD and not metrics["collision_before_t0"]
    assert 2.0 < metrics["collision_time_s"] <= 8.0
    assert metrics["kinematic_value_mps"] > 10.0       # the human drives on at ~20 m/s into a stopped car
    assert not metrics["adversary_off_road"] and not metrics["other_off_road"]
    # The adversary's recorder agent replays the spliced track; the ego is the human's record.
    adv = result.row_ids(record)[AHEAD]
    spliced = splice_tracks(record, tracks, [AHEAD])
    np.testing.assert_allclose(result.states[adv, 20:81:5, :2], spliced.states[record.agent_ids[AHEAD], 20:81:5, :2],
                               atol=1e-9)
    np.testing.assert_allclose(ego_future_2hz(result)[:, :2], record.window.states[0, 5:, :2], atol=1e-9)


def test_untouched_record_gives_no_collision(record):
    planner = cached_planner("replay")
    metrics = judge(record, np.zeros((0, 12, 6)), [], AHEAD, planner, "replay")
    assert not metrics["collision"] and not metrics["collision_any"]
    assert metrics["collision_type"] is None and metrics["kinematic_value_mps"] is None
    assert metrics["min_gap_m"] > 0.5 and metrics["distance_m"] > 60.0


def test_off_road_adversary_is_flagged(record):
    track = braking_track(record, AHEAD, decel_mps2=0.5)
    track[6:, 1] += 30.0                                  # far outside every lane after 3.5 s
    metrics = judge(record, track[None], [AHEAD], AHEAD, cached_planner("idm"), "idm")
    assert metrics["adversary_off_road"] and metrics["adversary_off_road_max"] == pytest.approx(1.0)
    assert not metrics["other_off_road"]


def test_reactive_ego_avoids_the_attack_and_is_untouched_before_t0(record):
    planner = cached_planner("idm")
    tracks = braking_track(record, AHEAD, decel_mps2=8.0)[None]
    attacked = rollout(record, tracks, [AHEAD], planner, "idm")
    calm = rollout(record, np.zeros((0, 12, 6)), [], planner, "idm")
    again = rollout(record, tracks, [AHEAD], planner, "idm")
    np.testing.assert_array_equal(attacked.states[attacked.ego], again.states[again.ego])   # deterministic
    np.testing.assert_array_equal(attacked.states[attacked.ego, :21], calm.states[calm.ego, :21])  # causal
    # The IDM/MOBIL human, unlike its played-back log, reacts: it changes lane around the stopping car.
    assert abs(attacked.states[attacked.ego, -1, 1] - calm.states[calm.ego, -1, 1]) > 2.0
    assert not judge(record, tracks, [AHEAD], AHEAD, planner, "idm", result=attacked)["collision"]
    np.testing.assert_array_equal(ego_future_2hz(attacked), attacked.states[attacked.ego, 25:81:5])
    np.testing.assert_array_equal(ego_track_2hz(attacked), attacked.states[attacked.ego, 0:81:5])
