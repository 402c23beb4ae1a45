"""Traffic lights from CommonRoad recordings: parsing, states over the cycle, lights without a
cycle, signals in scenes, and the route goal held at a red light (synthetic scenario, no data)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

pytest.importorskip("commonroad")

from rasterize.commonroad import (
    CommonRoadSceneConfig,
    RecordedTraffic,
    governing,
    movement_red,
    time_to_cover,
    turn_between,
)
from rasterize.config import Extent
from rasterize.highway import RouteRule
from tests.rasterize.signal_scenario import LENGTH, STOP_X, signal_scenario

RULE = RouteRule(accel_mps2=1.0)
CONFIG = CommonRoadSceneConfig(speed_limit_mps=15.0, route_rule=RULE)


@pytest.fixture(scope="module")
def traffic() -> RecordedTraffic:
    return RecordedTraffic(signal_scenario(), "synthetic")


def _light(traffic, light_id):
    return next(light for light in traffic.lights if light.light_id == light_id)


def test_lights_are_read_per_lanelet_at_their_stop_lines(traffic):
    pairs = [(light.lanelet_id, light.light_id) for light in traffic.lights]
    assert pairs == [(1, 10), (1, 11), (4, 12)]           # 13 has no cycle: left out
    np.testing.assert_allclose(_light(traffic, 10).stop_line, [[STOP_X, 1.75], [STOP_X, -1.75]])
    # Lanelet 4 has no stop line: its end, between the end points of its bounds.
    np.testing.assert_allclose(_light(traffic, 12).stop_line, [[0.0, 5.25], [0.0, 1.75]])
    np.testing.assert_allclose(_light(traffic, 10).forward, [1.0, 0.0])
    assert _light(traffic, 10).turns == {"straight", "right"} and _light(traffic, 11).turns == {"left"}
    assert set(traffic.lights_by_lanelet) == {1, 4}
    network = traffic.scenario.lanelet_network
    assert turn_between(network, 1, 2) == "straight" and turn_between(network, 1, 3) == "left"
    assert [light.light_id for light in governing(traffic.lights_by_lanelet[1], "left")] == [11]


def test_red_at_follows_the_cycle_and_repeats_it(traffic):
    light = _light(traffic, 10)                  # green 0-3 s, amber 3-4 s, red 4-10 s
    times = np.array([0.0, 2.95, 3.0, 3.95, 4.0, 9.95, 10.0, 13.5, 14.2, 21.0, -1.0])
    assert light.red_at(times).tolist() == [False, False, True, True, True, True, False, True, True,
                                              False, True]
    assert light.state_at(np.array([3.5]))[0] == "yellow"          # amber counts as red
    # The same states as commonroad-io's own cycle, over two periods and before the start.
    cr = traffic.scenario.lanelet_network.find_traffic_light_by_id(10)
    for step in range(-30, 230, 7):
        assert light.state_at(np.array([step * 0.1]))[0] == cr.get_state_at_time_step(step).value
    # A green arrow overrides a red ball; inactive lights do not hold a movement.
    left, straight = _light(traffic, 11), light
    assert movement_red([left], 1.0) and not movement_red([left], 6.0)
    assert not movement_red([left, straight], 1.0)                  # straight is green at 1 s
    assert not movement_red([], 5.0)


def test_signals_in_a_scene_hold_the_next_six_seconds(traffic):
    ego = traffic.index_of(100)
    scene = traffic.scene(ego, 30, CONFIG)                         # t = 3 s, ego at x = -30
    assert len(scene.signals) == 3
    by_line = {tuple(sig.stop_line[0]): sig for sig in scene.signals}
    np.testing.assert_allclose(scene.signals[0].times_s, 0.5 * np.arange(13))
    ten = scene.signals[0]                                          # light 10 (lanelet 1)
    # From 3 s to 9 s: amber, then red (4-10 s).
    assert ten.red.tolist() == [True] * 13 and not scene.signals[2].red_at(1.5)
    # From 6 s: red to 10 s, then green (10-13 s), past the recording's end (10 s): the cycle
    # goes on.
    later = traffic.scene(ego, 60, CONFIG).signals[0]
    assert later.red.tolist() == [True] * 8 + [False] * 5 and not later.red_at(4.2)
    assert (0.0, 5.25) in by_line
    # Only stop lines inside the scene's extent: 10 m ahead of an ego 28 m before them, none.
    near = traffic.scene(ego, 30, CommonRoadSceneConfig(extent=Extent(10.0, 5.0, 5.0, 5.0)))
    assert near.signals == ()
    wide = traffic.scene(ego, 30, CommonRoadSceneConfig(extent=Extent(40.0, 5.0, 5.0, 5.0)))
    assert len(wide.signals) == 3
    assert wide.rotated(0.7).signals[0].red.tolist() == wide.signals[0].red.tolist()


def test_a_light_without_a_cycle_is_unknown_warned_once_and_not_drawn(caplog):
    with caplog.at_level(logging.WARNING, logger="rasterize.commonroad"):
        first = RecordedTraffic(signal_scenario(), "no_cycle_file")
        again = RecordedTraffic(signal_scenario(), "no_cycle_file")
    warnings = [r.getMessage() for r in caplog.records if "no_cycle_file" in r.getMessage()]
    assert len(warnings) == 1 and "traffic light 13" in warnings[0] and "no cycle" in warnings[0]
    for traffic in (first, again):
        assert 13 not in {light.light_id for light in traffic.lights}
        scene = traffic.scene(traffic.index_of(102), 30, CONFIG)
        assert len(scene.signals) == 3                             # 10, 11, 12; never 13
    clean = RecordedTraffic(signal_scenario(with_uncycled_light=False), "no_cycle_file_2")
    assert [light.light_id for light in clean.lights] == [10, 11, 12]
    # A lanelet naming a light the file does not define: warned, left out.
    dangling = signal_scenario(with_uncycled_light=False)
    dangling.lanelet_network.find_lanelet_by_id(2).add_traffic_light_to_lanelet(99)
    with caplog.at_level(logging.WARNING, logger="rasterize.commonroad"):
        traffic = RecordedTraffic(dangling, "dangling_light_file")
    assert [light.light_id for light in traffic.lights] == [10, 11, 12]
    assert any("dangling_light_file" in r.getMessage() and "traffic light 99" in r.getMessage()
               for r in caplog.records)


def _state(x: float, speed: float, y: float = 0.0) -> np.ndarray:
    return np.array([x, y, 1.0, 0.0, speed, 0.0])


def _route_end(traffic, agent_id, state, now_s) -> np.ndarray:
    return traffic.route(traffic.index_of(agent_id), state, np.zeros((0, 6)), np.zeros(0), now_s,
                         CONFIG)[-1]


def test_the_goal_is_held_before_a_red_light_and_released_on_green(traffic):
    state = _state(-30.0, 5.0)
    front_to_line = STOP_X - (-30.0) - LENGTH / 2
    arrival = time_to_cover(front_to_line, 5.0, RULE.accel_mps2, 15.0)
    assert 3.0 < arrival < 5.0
    # Light 10 (straight) is red from 4 to 10 s: arriving at 5 + arrival s the goal waits.
    held = _route_end(traffic, 100, state, 5.0 - arrival + 2.0)
    assert STOP_X - 2.0 - LENGTH / 2 - 1.0 < held[0] <= STOP_X - 2.0      # ~2 m before the line
    assert held[0] + LENGTH / 2 <= STOP_X                                 # the front short of it
    # Arriving when it is green (10-13 s) the goal passes through the intersection.
    released = _route_end(traffic, 100, state, 11.0 - arrival)
    assert released[0] > 5.0
    # Green now but red when the ego would get there: held.
    assert _route_end(traffic, 100, state, 1.5)[0] <= STOP_X - 2.0


def test_the_route_turns_the_way_the_recorded_vehicle_did_under_its_own_light(traffic):
    state = _state(-30.0, 5.0)
    arrival = time_to_cover(STOP_X + 30.0 - LENGTH / 2, 5.0, RULE.accel_mps2, 15.0)
    now = 6.5 - arrival            # arrival at 6.5 s: straight (10) red, left (11) green
    straight, left = _route_end(traffic, 100, state, now), _route_end(traffic, 101, state, now)
    assert straight[0] <= STOP_X - 2.0                                  # held at the line
    assert left[0] > 0.0 and left[1] > 1.0                              # into the left turn
    now = 2.0 - arrival            # arrival at 2 s: straight green, left red
    assert _route_end(traffic, 100, state, now)[0] > 5.0
    assert _route_end(traffic, 101, state, now)[0] <= STOP_X - 2.0


def test_a_moving_ego_that_cannot_stop_goes_and_a_waiting_one_stays(traffic):
    # Front already 0.25 m past the stop line on red at 8 m/s: committed, the goal is ahead.
    assert _route_end(traffic, 100, _state(STOP_X - LENGTH / 2 + 0.25, 8.0), 5.0)[0] > STOP_X
    # 5 m before it at 12 m/s (24 m to stop at 3 m/s²): committed too.
    assert _route_end(traffic, 100, _state(STOP_X - LENGTH / 2 - 5.0, 12.0), 5.0)[0] > STOP_X
    # Waiting with the front 1.5 m past the line (as NGSIM drivers do): held where it is until
    # green (10 s); once its rear is past, the line is behind it.
    waiting = _state(STOP_X - LENGTH / 2 + 1.5, 0.0)
    np.testing.assert_allclose(_route_end(traffic, 100, waiting, 5.0), waiting[:2])
    assert _route_end(traffic, 100, waiting, 10.5)[0] > waiting[0] + 1.0
    assert _route_end(traffic, 100, _state(STOP_X + LENGTH / 2 + 0.1, 0.5), 5.0)[0] > STOP_X + 2.0


def test_a_lanelet_without_successor_ends_the_route(traffic):
    # On lanelet 2 (no successor) the route stops at its end (x = 50) however far it could go.
    end = _route_end(traffic, 100, _state(30.0, 12.0), 0.0)
    assert end[0] == pytest.approx(50.0)
