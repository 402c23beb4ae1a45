"""The solution check's lateral alternative (one lane over), and that it is off by default."""

import numpy as np
import pytest

from rasterize.tracks import Tracks
from riskmap.sim.records.alternatives import ego_only_solution


def _stopped_car_close_ahead():
    """Ego at 20 m/s along y = 0 (dt 0.1 s, 31 steps); a stopped car at x = 28 in its lane:
    even -8 m/s² from 3 s before needs 25 m, only 23 m are free, so braking alone fails."""
    steps = 31
    states = np.zeros((2, steps, 6))
    states[0, :, 0] = 2.0 * np.arange(steps)
    states[:, :, 2] = 1.0
    states[0, :, 4] = 20.0
    states[1, :, 0] = 28.0
    return Tracks(states, np.ones((2, steps), bool), np.array([[5.0, 2.0], [5.0, 2.0]]), np.zeros(2, np.int8))


def _road(y_min: float, y_max: float):
    def on_road(centre, heading, length, width):
        return y_min + 0.5 * width <= centre[1] <= y_max - 0.5 * width
    return on_road


def test_braking_alone_cannot_avoid_a_close_stopped_car():
    tracks = _stopped_car_close_ahead()
    assert not ego_only_solution(tracks, ego=0, collision_step=30, dt_s=0.1)


def test_moving_one_lane_over_avoids_it_where_that_lane_exists():
    tracks = _stopped_car_close_ahead()
    assert ego_only_solution(tracks, ego=0, collision_step=30, dt_s=0.1,
                             lateral_offsets_m=(4.0, -4.0), on_road=_road(-2.0, 6.0))


def test_no_lateral_solution_on_a_one_lane_road():
    tracks = _stopped_car_close_ahead()
    assert not ego_only_solution(tracks, ego=0, collision_step=30, dt_s=0.1,
                                 lateral_offsets_m=(4.0, -4.0), on_road=_road(-2.0, 2.0))


def test_lateral_alternatives_need_a_road():
    tracks = _stopped_car_close_ahead()
    with pytest.raises(ValueError):
        ego_only_solution(tracks, ego=0, collision_step=30, dt_s=0.1, lateral_offsets_m=(4.0,))
