"""Gap keeping: the planned timing never runs into a vehicle predicted on the path."""

import numpy as np
import pytest

from rasterize.scene import Scene
from riskmap.planner.gap_keeping import GapKeepingConfig, keep_gap
from tests.scenes import state

WIDE = GapKeepingConfig(standstill_m=2.0, headway_s=1.0)               # round numbers
STRAIGHT = np.column_stack([5.0 * np.arange(1, 13), np.zeros(12)])   # 10 m/s for 6 s


def _scene(other: list[float]) -> Scene:
    """Ego at the origin heading +x at 10 m/s (box 5 x 2 m) and one other vehicle (5 x 2 m)."""
    states = np.array([[state(0.0, 0.0, 0.0, 10.0)], [other]], dtype=float)
    return Scene(states, np.ones((2, 1), bool), sizes=np.array([[5.0, 2.0], [5.0, 2.0]]),
                 kinds=np.zeros(2), ego_index=0, current_index=0, dt=0.5)


def test_a_standing_vehicle_ahead_caps_the_plan_short_of_it():
    out = keep_gap(STRAIGHT, _scene(state(30.0, 0.0, 0.0, 0.0)), 0.5, WIDE)
    # 30 m ahead, less half the two lengths (5 m) and the 2 m standstill gap: stop at 23 m.
    np.testing.assert_allclose(out[:, 0], np.minimum(5.0 * np.arange(1, 13), 23.0), atol=1e-9)
    np.testing.assert_allclose(out[:, 1], 0.0, atol=1e-9)


def test_a_slower_leader_is_followed_at_its_gap_and_headway():
    # Leader 20 m ahead at 4 m/s: at t it is at 20 + 4t; cap = 20 + 4t - 5 - 2 - 1.0 * 4 = 9 + 4t.
    out = keep_gap(STRAIGHT, _scene(state(20.0, 0.0, 0.0, 4.0)), 0.5, WIDE)
    t = 0.5 * np.arange(1, 13)
    cap = 9.0 + 4.0 * t
    np.testing.assert_allclose(out[:, 0], np.minimum(10.0 * t, cap), atol=1e-9)
    assert np.all(np.diff(out[:, 0]) >= 0)


@pytest.mark.parametrize("other", [
    state(30.0, 3.7, 0.0, 0.0),     # standing in the next lane
    state(-10.0, 0.0, 0.0, 15.0),   # behind, faster: not a leader
    state(20.0, 0.0, 0.0, 12.0),    # ahead and faster: never reached
])
def test_nobody_in_the_way_leaves_the_plan_unchanged(other):
    np.testing.assert_array_equal(keep_gap(STRAIGHT, _scene(other), 0.5), STRAIGHT)


def test_a_vehicle_cutting_in_later_caps_from_then_on():
    # 25 m ahead in the next lane, crossing to the right at 1.85 m/s: on the path (within 2.3 m
    # of it) from t = 1 to 3 s, standing still along x. Up to 3 s the ego stays 7 m short of it;
    # then it goes on at the planned 10 m/s, never jumping ahead.
    crossing = state(25.0, 3.7, -np.pi / 2, 1.85)
    out = keep_gap(STRAIGHT, _scene(crossing), 0.5, WIDE)
    t = 0.5 * np.arange(1, 13)
    expected = np.concatenate([np.minimum(10.0 * t[:6], 18.0), 18.0 + 5.0 * np.arange(1, 7)])
    np.testing.assert_allclose(out[:, 0], expected, atol=1e-9)


def test_the_default_gap_is_a_metre_behind_the_prediction():
    out = keep_gap(STRAIGHT, _scene(state(30.0, 0.0, 0.0, 0.0)), 0.5)
    np.testing.assert_allclose(out[:, 0], np.minimum(5.0 * np.arange(1, 13), 24.0), atol=1e-9)


def test_lanes_prediction_sees_a_car_turning_across_the_path():
    """A car 30 m ahead and 12 m to the left, heading west on a lane that turns south across the
    ego's path at x = 12 m (in ~4 s at 6 m/s): along its lane it is in the way, along its heading
    it never is."""
    from rasterize.scene import Lane

    straight = np.stack([np.linspace(30.0, 24.0, 7), np.full(7, 12.0)], axis=1)
    angle = np.linspace(np.pi / 2, np.pi, 20)[1:]
    arc = np.stack([24.0 + 12.0 * np.cos(angle), 12.0 * np.sin(angle)], axis=1)
    south = np.stack([np.full(10, 12.0), np.linspace(-2.0, -20.0, 10)], axis=1)
    centre = np.concatenate([straight, arc, south])
    tangent = np.gradient(centre, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    left = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    lane = Lane(centre, centre + 2.0 * left, centre - 2.0 * left)
    states = np.array([[state(0.0, 0.0, 0.0, 5.0)], [[30.0, 12.0, -1.0, 0.0, 6.0, 0.0]]])
    scene = Scene(states, np.ones((2, 1), bool), np.array([[5.0, 2.0]] * 2), np.zeros(2, np.int8),
                  0, 0, 0.1, lanes=(lane,))
    plan = np.stack([2.5 * np.arange(1, 13), np.zeros(12)], axis=1)
    assert np.array_equal(keep_gap(plan, scene, 0.5, prediction="straight"), plan)
    held = keep_gap(plan, scene, 0.5, prediction="lanes")
    assert held[:8, 0].max() < 12.0 - 5.0 + 1e-6    # short of the crossing until it has passed
