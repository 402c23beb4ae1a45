"""Per-step maps of the space-time planner, on hand-built scenes (UNIT_GRID: 1 m cells, the ego's
cell (10, 10); row 10 − k holds x in (k − 1, k])."""

import numpy as np
import pytest

from rasterize.errors import InputError
from rasterize.maps import footprint_map, uncertainty_map
from rasterize.scene import Scene, Signal
from rasterize.spacetime import (
    EVIDENCE_CHANNELS,
    demo_cells_per_step,
    future_footprints,
    predicted_footprints,
    red_stop_lines,
    step_evidence,
)
from tests.scenes import UNIT_GRID, state


def crossing_scene(steps: int = 4, dt: float = 0.5, ego_speed: float = 2.0) -> Scene:
    """Ego east at `ego_speed` from the origin; an agent at (6.5, −6.5) heading north at 4 m/s
    (it crosses the ego's lane 1.5 s from now, mid-cell at every step); `steps` future steps."""
    t = np.arange(-2, steps + 1) * dt
    ego = [state(ego_speed * ti, 0.0, 0.0, ego_speed) for ti in t]
    agent = [state(6.5, -6.5 + 4.0 * ti, np.pi / 2, 4.0) for ti in t]
    return Scene(np.array([ego, agent]), np.ones((2, len(t)), bool), np.array([[4.0, 2.0]] * 2),
                 np.zeros(2), ego_index=0, current_index=2, dt=dt)


def test_demo_cells_are_where_the_ego_is_at_each_step():
    cells = demo_cells_per_step(crossing_scene(), UNIT_GRID, 4, 0.5)
    # x = 1, 2, 3, 4 m ahead: rows 9, 8, 7, 6 (x in (k − 1, k] lies in row 10 − k); y = 0: col 10
    np.testing.assert_array_equal(cells, [[9, 10], [8, 10], [7, 10], [6, 10]])


def test_demo_cells_off_the_grid_are_minus_one():
    cells = demo_cells_per_step(crossing_scene(ego_speed=8.0), UNIT_GRID, 4, 0.5)
    # 4, 8, 12, 16 m: the grid reaches 10 m ahead
    assert (cells[:2] >= 0).all() and (cells[2:] == -1).all()


def test_future_footprints_follow_the_recorded_agent():
    maps = future_footprints(crossing_scene(), UNIT_GRID, 4, 0.5)
    assert maps.shape == (4, 20, 20)
    for t in range(4):                       # the agent at (6.5, −6.5 + 2 (t + 1))
        y = -6.5 + 2.0 * (t + 1)
        expected = footprint_map(np.array([[6.5, y]]), np.array([np.pi / 2]), UNIT_GRID)
        np.testing.assert_array_equal(maps[t], expected)
        row, col = np.unravel_index(maps[t].argmax(), maps[t].shape)
        assert row == 3 and col == 10 - int(np.ceil(y))          # x = 6.5: row 3; y: col


def test_predicted_footprints_read_the_present_only():
    scene = crossing_scene()
    stopped = scene.states.copy()
    stopped[1, 3:, :2] = stopped[1, 2, :2]          # the recorded future: the agent stops
    other = Scene(stopped, scene.valid, scene.sizes, scene.kinds, 0, 2, 0.5)
    np.testing.assert_array_equal(predicted_footprints(scene, UNIT_GRID, 4, 0.5),
                                  predicted_footprints(other, UNIT_GRID, 4, 0.5))
    # no lanes: it keeps its velocity, so at step 3 (1.5 s) it is on the ego's lane at (6.5, −0.5)
    maps = predicted_footprints(scene, UNIT_GRID, 4, 0.5)
    np.testing.assert_allclose(maps, future_footprints(scene, UNIT_GRID, 4, 0.5), atol=1e-6)
    assert maps[2, 3, 10] > 0.5 and maps[0, 3, 10] < 0.1


def test_now_is_the_uncertainty_map():
    scene = crossing_scene()
    now = footprint_map(np.array([[6.5, -6.5]]), np.array([np.pi / 2]), UNIT_GRID)
    np.testing.assert_array_equal(uncertainty_map(scene, UNIT_GRID), now)


def test_red_stop_lines_at_the_steps_the_light_is_red():
    light = Signal(stop_line=np.array([[5.0, -2.0], [5.0, 2.0]]), times_s=np.array([0.0, 1.2]),
                   red=np.array([False, True]))
    scene = crossing_scene()
    import dataclasses

    scene = dataclasses.replace(scene, signals=(light,))
    maps = red_stop_lines(scene, UNIT_GRID, 4, 0.5)
    assert maps[:2].sum() == 0                                 # 0.5 s, 1 s: green
    assert (maps[2:, 5, 8:12] == 1).all() and maps[2:].sum() == 2 * 5   # x = 5 m: row 5; y ∈ [−2, 2]
    evidence = step_evidence(scene, UNIT_GRID, 4, 0.5)
    assert evidence.shape == (4, len(EVIDENCE_CHANNELS), 20, 20)
    np.testing.assert_array_equal(evidence[:, 1], maps)


def test_a_short_recording_is_one_clear_error():
    with pytest.raises(InputError, match="needs 6 s"):
        demo_cells_per_step(crossing_scene(steps=4), UNIT_GRID, 12, 0.5)
    with pytest.raises(InputError, match="does not divide"):
        future_footprints(crossing_scene(dt=0.4), UNIT_GRID, 2, 0.5)
