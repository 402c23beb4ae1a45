from dataclasses import replace

import numpy as np
import pytest

from rasterize.predict import predict_along_lanes, prediction_times
from rasterize.scene import Lane, Scene
from tests.scenes import state, straight_lane


def arc_lane(centre, radius, start_rad, end_rad, points=181) -> Lane:
    """A lane along a circle, counter-clockwise from start_rad to end_rad (4 m wide)."""
    theta = np.linspace(start_rad, end_rad, points)
    radial = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    c = np.asarray(centre, dtype=float) + radius * radial
    # Counter-clockwise: the left of the driving direction is towards the circle's centre.
    return Lane(c, c - 2.0 * radial, c + 2.0 * radial)


def scene_of(agent_states, lanes=(), future=None) -> Scene:
    """Agent 0 is a parked ego far away; the others are `agent_states` now (one past step).

    `future` [N-1, F, 6] optionally records their future after now.
    """
    now = [state(0.0, 100.0, 0.0)] + list(agent_states)
    states = np.array(now, dtype=float)[:, None].repeat(2, axis=1)
    if future is not None:
        ego_future = np.repeat(states[:1, -1:], future.shape[1], axis=1)
        states = np.concatenate([states, np.concatenate([ego_future, future])], axis=1)
    n = len(now)
    return Scene(states, np.ones(states.shape[:2], bool), np.tile([4.0, 2.0], (n, 1)),
                 np.zeros(n), ego_index=0, current_index=1, dt=0.5, lanes=tuple(lanes))


def test_prediction_times_end_at_the_horizon():
    np.testing.assert_allclose(prediction_times(3.0), [0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
    np.testing.assert_allclose(prediction_times(1.2), [0.5, 1.0, 1.2])
    assert prediction_times(0.0).shape == (0,)


def test_straight_lane_snaps_to_the_centre_and_follows_the_lane_not_the_heading():
    # 1 m left of the lane's centre, heading 20 deg off it at 4 m/s.
    scene = scene_of([state(-8.0, 1.0, np.deg2rad(20), 4.0)], lanes=[straight_lane(0.0)])
    xy, heading = predict_along_lanes(scene, 2.0)
    np.testing.assert_allclose(xy[1], [[-6, 0], [-4, 0], [-2, 0], [0, 0]], atol=1e-9)
    np.testing.assert_allclose(heading[1], np.tile([1.0, 0.0], (4, 1)), atol=1e-12)


def test_curved_lane_is_followed_with_the_tangent_as_heading():
    # Circle of radius 10 about (10, -15), entered at its bottom heading east, 8 m/s, 3 s.
    lane = arc_lane((10.0, -15.0), 10.0, -np.pi / 2, np.pi / 2)
    scene = scene_of([state(10.0, -25.0, 0.0, 8.0)], lanes=[lane])
    xy, heading = predict_along_lanes(scene, 3.0)
    theta = -np.pi / 2 + 8.0 * prediction_times(3.0) / 10.0
    expected = np.array([10.0, -15.0]) + 10.0 * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    # The polyline's chords cut the circle by at most R (1 - cos(0.5 deg)) ~ 0.4 mm.
    np.testing.assert_allclose(xy[1], expected, atol=0.01)
    np.testing.assert_allclose(heading[1], np.stack([-np.sin(theta), np.cos(theta)], axis=1),
                               atol=0.01)


def test_junction_goes_straight_without_yaw_rate_and_turns_with_it():
    approach = straight_lane(0.0, -20.0, 0.0)
    straight = straight_lane(0.0, 0.0, 20.0)
    left = arc_lane((0.0, 10.0), 10.0, -np.pi / 2, 0.0)    # turns north from (0, 0)
    lanes = [approach, left, straight]
    xy, _ = predict_along_lanes(scene_of([state(-10.0, 0.0, 0.0, 10.0)], lanes), 2.0)
    np.testing.assert_allclose(xy[1, -1], [10.0, 0.0], atol=1e-6)
    # Yaw rate v / R: the agent is turning at the rate of the left lane.
    xy, heading = predict_along_lanes(scene_of([state(-10.0, 0.0, 0.0, 10.0, 1.0)], lanes), 2.0)
    np.testing.assert_allclose(xy[1, -1], [10 * np.sin(1.0), 10 - 10 * np.cos(1.0)], atol=0.01)
    np.testing.assert_allclose(heading[1, -1], [np.cos(1.0), np.sin(1.0)], atol=0.01)


def test_past_the_last_lane_it_carries_on_straight():
    xy, heading = predict_along_lanes(scene_of([state(-4.0, 0.0, 0.0, 4.0)],
                                               [straight_lane(0.0, -10.0, 0.0)]), 2.0)
    np.testing.assert_allclose(xy[1], [[-2, 0], [0, 0], [2, 0], [4, 0]], atol=1e-9)
    np.testing.assert_allclose(heading[1, -1], [1.0, 0.0])


@pytest.mark.parametrize("agent", [
    state(-8.0, 0.0, np.pi / 2, 4.0),       # crossing the lane: no lane runs its way
    state(-8.0, 0.0, np.pi, 4.0),           # against the lane's direction
    state(-8.0, 3.5, 0.0, 4.0),             # 3.5 m beside the centre line
])
def test_without_a_matching_lane_the_velocity_is_kept(agent):
    xy, heading = predict_along_lanes(scene_of([agent], [straight_lane(0.0)]), 1.0)
    fwd = np.array(agent[2:4])
    np.testing.assert_allclose(xy[1], np.array(agent[:2]) + np.outer([2.0, 4.0], fwd), atol=1e-9)
    np.testing.assert_allclose(heading[1], np.tile(fwd, (2, 1)), atol=1e-12)


def test_only_the_present_is_read():
    lanes = [straight_lane(0.0)]
    calm = scene_of([state(-8.0, 0.0, 0.0, 4.0)], lanes, future=np.array([[state(-6, 0, 0, 4)] * 4]))
    wild = replace(calm, states=calm.states.copy())
    wild.states[1, 2:] = state(30.0, -20.0, 2.0, 15.0, 1.0)
    for a, b in zip(predict_along_lanes(calm, 2.0), predict_along_lanes(wild, 2.0)):
        np.testing.assert_array_equal(a, b)


def test_absent_agents_are_nan():
    scene = scene_of([state(-8.0, 0.0, 0.0, 4.0), state(5.0, 0.0, 0.0, 4.0)], [straight_lane(0.0)])
    valid = scene.valid.copy()
    valid[2, 1] = False
    xy, heading = predict_along_lanes(replace(scene, valid=valid), 1.0)
    assert np.isnan(xy[2]).all() and np.isnan(heading[2]).all() and np.isfinite(xy[:2]).all()
