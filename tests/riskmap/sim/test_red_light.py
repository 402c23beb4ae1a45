"""Red-light violations: the stop-line crossing metric, the lanelet-aware counter on a synthetic
signalised intersection, the closed loop's count, and the record's fields."""

from __future__ import annotations

import numpy as np
import pytest

from riskmap.sim.records.metrics import stop_line_crossings
from riskmap.sim.records.record import CORE_FIELDS, EpisodeRecord

LINE = np.array([[0.0, 1.75], [0.0, -1.75]])
EAST = np.array([1.0, 0.0])


def _drive(x0: float, speed: float, seconds: float, y: float = 0.0, t0: float = 0.0,
           heading=(1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    t = t0 + 0.1 * np.arange(round(seconds / 0.1) + 1)
    states = np.zeros((len(t), 6))
    states[:, 0] = x0 + speed * (t - t0) * heading[0]
    states[:, 1] = y + speed * (t - t0) * heading[1]
    states[:, 2:4] = heading
    states[:, 4] = speed
    return t, states


def test_a_front_crossing_the_line_forwards_counts_once_at_the_interpolated_time():
    t, states = _drive(-10.0, 10.0, 2.0)                     # front (x + 2.25) at 0 at 0.775 s
    assert stop_line_crossings(t, states, 4.5, LINE, EAST) == [pytest.approx(0.775)]
    # Beside the line (the next lane), backwards, or across the lane: no crossing.
    assert stop_line_crossings(*_drive(-10.0, 10.0, 2.0, y=3.5), 4.5, LINE, EAST) == []
    t_back, back = _drive(10.0, 10.0, 2.0, heading=(-1.0, 0.0))
    assert stop_line_crossings(t_back, back, 4.5, LINE, EAST) == []
    t_cross, cross = _drive(-1.0, 5.0, 2.0, y=-6.0, heading=(0.0, 1.0))
    assert stop_line_crossings(t_cross, cross, 4.5, LINE, EAST) == []
    # Stopping short of it, or starting beyond it: nothing to count.
    t_stop, stop = _drive(-10.0, 0.0, 2.0)
    assert stop_line_crossings(t_stop, stop, 4.5, LINE, EAST) == []
    assert stop_line_crossings(*_drive(1.0, 10.0, 2.0), 4.5, LINE, EAST) == []
    # Forward over, back behind, forward again: two crossings.
    x = np.array([-4.0, -2.0, -1.0, -3.0, -1.5, 0.0])
    states = np.zeros((len(x), 6))
    states[:, 0], states[:, 2] = x, 1.0
    assert len(stop_line_crossings(np.arange(len(x)) * 0.1, states, 4.5, LINE, EAST)) == 2


pytest.importorskip("commonroad")

from rasterize.commonroad import RecordedTraffic
from riskmap.sim.worlds.commonroad_replay import (
    RecordedFuturePlanner,
    ReplayConfig,
    red_light_events,
    replay_commonroad_episode,
)
from tests.rasterize.signal_scenario import STOP_X, signal_scenario


@pytest.fixture(scope="module")
def traffic() -> RecordedTraffic:
    return RecordedTraffic(signal_scenario(), "synthetic_red_light")


def _violations(traffic, agent_id, t, states) -> int:
    return sum(e["red"] for e in red_light_events(traffic, traffic.index_of(agent_id), t, states))


def test_crossing_on_red_counts_once_and_on_green_not(traffic):
    # Straight on along lanelet 1: the front reaches the line (x = -2) at 0.575 s after x = -10.
    t, states = _drive(STOP_X - 8.0, 10.0, 3.0, t0=4.5)      # crossing at 5.075 s: red (4-10 s)
    events = red_light_events(traffic, traffic.index_of(100), t, states)
    assert [(e["lanelet"], e["turn"], e["red"]) for e in events] == [(1, "straight", True)]
    assert events[0]["lights"] == {"10": "red"} and events[0]["time_s"] == pytest.approx(5.08, abs=0.01)
    t, states = _drive(STOP_X - 8.0, 10.0, 3.0, t0=10.5)     # crossing at 11.075 s: green
    assert _violations(traffic, 100, t, states) == 0
    t, states = _drive(STOP_X - 8.0, 10.0, 3.0, t0=12.7)     # at 13.275 s: amber counts as red
    assert _violations(traffic, 100, t, states) == 1


def test_a_signal_on_another_lane_does_not_count(traffic):
    # On lanelet 1 at 0.575 s: light 10 is green while lanelet 4's light 12 is red (0-4 s).
    t, states = _drive(STOP_X - 8.0, 10.0, 3.0)
    assert traffic.lights_by_lanelet[4][0].red_at(np.array([0.575]))[0]
    events = red_light_events(traffic, traffic.index_of(100), t, states)
    assert [e["lanelet"] for e in events] == [1] and _violations(traffic, 100, t, states) == 0


def test_the_light_of_the_turn_taken_decides(traffic):
    # Vehicle 101 turns left: it crosses at 5.575 s, when straight (10) is red and left (11) green.
    ego = traffic.index_of(101)
    first, last = traffic.span(ego)
    t = np.arange(first, last + 1) * traffic.dt_s
    events = red_light_events(traffic, ego, t, traffic.states[ego, first: last + 1])
    assert [(e["turn"], e["red"]) for e in events] == [("left", False)]
    # Vehicle 100, straight on, crosses at 4.53 s on red.
    ego = traffic.index_of(100)
    events = red_light_events(traffic, ego, t, traffic.states[ego, first: last + 1])
    assert [(e["turn"], e["red"]) for e in events] == [("straight", True)]


@pytest.mark.parametrize("vehicle, expected", [(100, 1), (101, 0), (102, 0)])
def test_closed_loop_replay_counts_the_human_reference(traffic, vehicle, expected):
    result = replay_commonroad_episode(traffic, vehicle, RecordedFuturePlanner(traffic, vehicle),
                                       config=ReplayConfig(mode="log"))
    assert result["red_light_violations"] == expected
    assert result["human_red_light_violations"] == expected
    assert len(result["signal_crossings"]) == 1 and result["yield_events"] == 0


def test_the_record_has_the_counts_with_defaults():
    assert {"red_light_violations", "yield_events"} <= set(CORE_FIELDS)
    record = EpisodeRecord.measured("cv", False, False, 1.0, 10.0, [10.0], [5.0], [])
    assert record.red_light_violations == 0 and record.yield_events == 0
    assert EpisodeRecord.from_dict({"planner": "cv", "collided": False}).red_light_violations == 0
    moved = EpisodeRecord.measured("cv", False, False, 1.0, 10.0, [10.0], [5.0], [],
                                   extra={"yield_events": 2}, red_light_violations=3)
    assert (moved.yield_events, moved.red_light_violations, moved.extra) == (2, 3, {})
    assert EpisodeRecord.from_dict(moved.as_dict()) == moved
