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


@pytest.mark.parametrize("extent_rows_cols", [((40.0, 8.0, 6.0, 6.0), 10, 15),     # long cells
                                              ((10.0, 10.0, 10.0, 10.0), 20, 20)])  # square
def test_footprint_maps_match_a_float64_reference_without_a_cut(extent_rows_cols):
    """Every sub-sample point of every cell against every agent, in float64 and with no 4-sigma
    window: the drawn maps differ only by what lies beyond 4 sigma (at most e^-8) and rounding."""
    from rasterize.config import Extent, GridConfig
    from rasterize.frames import ego_from_grid
    from rasterize.maps import _subcell_offsets, footprint_maps

    (front, back, left, right), rows, cols = extent_rows_cols
    grid = GridConfig(Extent(front, back, left, right), rows, cols)
    rng = np.random.default_rng(3)
    centres = np.column_stack([rng.uniform(-back - 5, front + 5, 14), rng.uniform(-right - 3, left + 3, 14)])
    headings = rng.uniform(-np.pi, np.pi, 14)
    layer = rng.integers(0, 3, 14)
    sigma_x, sigma_y = 0.5, 1.5
    drawn = footprint_maps(centres, headings, layer, 3, grid, sigma_x, sigma_y)
    cells = ego_from_grid(np.stack(np.indices((rows, cols)), -1), grid)                 # [R, C, 2]
    points = cells[:, :, None, :] + _subcell_offsets(grid)                               # [R, C, S, 2]
    expected = np.zeros((3, rows, cols))
    for t in range(3):
        best = np.zeros(points.shape[:3])
        for (x, y), h in zip(centres[layer == t], headings[layer == t]):
            dx, dy = points[..., 0] - x, points[..., 1] - y
            along, across = dx * np.cos(h) + dy * np.sin(h), -dx * np.sin(h) + dy * np.cos(h)
            best = np.maximum(best, np.exp(-0.5 * ((along / sigma_y) ** 2 + (across / sigma_x) ** 2)))
        expected[t] = best.mean(axis=2)
    assert drawn.dtype == np.float32 and drawn.shape == (3, rows, cols)
    assert expected.max() > 0.2                       # the agents are on the grid
    np.testing.assert_allclose(drawn, expected, rtol=0, atol=np.exp(-8.0) + 1e-6)


def test_agents_sharing_cells_combine_by_maximum():
    """Two agents of one layer on the same spot draw what one draws; a third beside them raises
    the cells it covers to its own values where those are larger, in each layer apart."""
    from rasterize.config import Extent, GridConfig
    from rasterize.maps import footprint_maps

    grid = GridConfig(Extent(10.0, 10.0, 10.0, 10.0), 20, 20)
    one = footprint_maps(np.array([[1.0, 2.0]]), np.array([0.3]), np.array([0]), 2, grid)
    two = footprint_maps(np.array([[1.0, 2.0], [1.0, 2.0]]), np.array([0.3, 0.3]),
                         np.array([0, 0]), 2, grid)
    np.testing.assert_array_equal(one, two)
    beside = footprint_maps(np.array([[1.5, 2.5]]), np.array([0.0]), np.array([0]), 2, grid)
    both = footprint_maps(np.array([[1.0, 2.0], [1.5, 2.5]]), np.array([0.3, 0.0]),
                          np.array([0, 0]), 2, grid)
    assert (both >= np.maximum(one, beside) - 1e-7).all() and not both[1].any()
    assert (both > np.maximum(one, beside)).any()     # per sub-sample maximum, then the mean
