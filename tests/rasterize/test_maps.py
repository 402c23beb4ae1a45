from dataclasses import replace

import numpy as np
import pytest

from rasterize.config import Extent, GridConfig
from rasterize.errors import InputError
from rasterize.maps import (
    demo_goal_cell,
    demo_visitation,
    goal_map,
    motion_features,
    start_cell,
    uncertainty_map,
)
from tests.scenes import UNIT_GRID, constant_velocity_scene, state


def test_uncertainty_peaks_on_the_agent_and_is_rotated_by_its_heading():
    scene = constant_velocity_scene()   # agent at ego (5, 3), facing north = ego's left
    u = uncertainty_map(scene, UNIT_GRID, sigma_x=0.5, sigma_y=1.5)
    assert u.shape == (20, 20) and u.dtype == np.float32 and 0 <= u.min() and u.max() <= 1
    # x = 5 lies on the edge between rows 4 and 5, y = 3 on the edge between cols 6 and 7.
    peak = np.unravel_index(np.argmax(u), u.shape)
    assert peak[0] in (4, 5) and peak[1] in (6, 7)
    # Facing the ego's left, the long sigma (1.5 m, along the agent) runs across the columns.
    along_cols = u[4, 3:11].sum()
    along_rows = u[1:9, 6].sum()
    assert along_cols > 1.5 * along_rows
    # The ego itself carries no uncertainty.
    assert u[9:11, 9:11].max() < 1e-6


def test_uncertainty_matches_a_float64_point_reference_for_small_cells():
    # With cells much smaller than sigma, the cell mean equals the Gaussian at the centre.
    grid = GridConfig(Extent(10.0, 10.0, 10.0, 10.0), rows=200, cols=200)
    u = uncertainty_map(constant_velocity_scene(), grid, sigma_x=1.0, sigma_y=2.0)
    r, c = 40, 60                                    # cell centre x = 5.95, y = 3.95
    x, y = 10 - (r + 0.5) * 0.1, 10 - (c + 0.5) * 0.1
    along, across = y - 3.0, -(x - 5.0)              # agent faces +y
    ref = np.exp(-0.5 * ((along / 2.0) ** 2 + (across / 1.0) ** 2))
    assert u[r, c] == pytest.approx(ref, rel=1e-3)


def test_uncertainty_rejects_bad_sigma():
    with pytest.raises(InputError, match="sigmas"):
        uncertainty_map(constant_velocity_scene(), UNIT_GRID, sigma_x=0.0)


def test_goal_map_is_a_gaussian_in_cells():
    g = goal_map((3, 4), UNIT_GRID, variance=5.0)
    assert g[3, 4] == pytest.approx(1.0)
    assert g[3, 6] == pytest.approx(np.exp(-0.5 * 4 / 5.0))
    assert g[5, 6] == pytest.approx(np.exp(-0.5 * 8 / 5.0))


def test_demo_visitation_straight_path():
    # Ego at 2 m/s for 4 x 0.5 s: 4 m straight ahead. The ego's centre is the corner of four
    # cells; floor puts it in (10, 10), which covers x in [0, 1), y in [0, 1) to the right.
    counts, goal = demo_visitation(constant_velocity_scene(ego_speed=2.0), UNIT_GRID)
    assert start_cell(UNIT_GRID) == (10, 10)
    path = np.argwhere(counts > 0)
    np.testing.assert_array_equal(sorted(map(tuple, path)), [(r, 10) for r in range(6, 11)])
    assert counts.sum() == 5 and goal.sum() == 1 and goal[6, 10] == 1


def _scene_with_ego_future(points, dt=0.5):
    base = constant_velocity_scene(n_past=1, n_future=len(points))
    states = base.states.copy()
    for k, (x, y) in enumerate(points):
        states[0, 2 + k] = state(x, y, 0.0, 1.0)
    return replace(base, states=states)


def test_demo_visitation_diagonal_path_is_four_connected_and_counts_revisits():
    scene = _scene_with_ego_future([(3.3, 3.1), (0.2, 0.3)])  # out diagonally and back
    counts, goal = demo_visitation(scene, UNIT_GRID)
    assert goal[9, 9] == 1                  # ends 0.2 m ahead, 0.3 m left: cell (9, 9)
    assert counts[10, 10] == 1 and counts.sum() >= 8
    # 4-connectivity: every visited cell but the start has a visited 4-neighbour.
    cells = {tuple(c) for c in np.argwhere(counts > 0)}
    for r, c in cells:
        assert any((r + dr, c + dc) in cells for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)))


def test_demo_goal_is_the_last_in_grid_cell():
    scene = _scene_with_ego_future([(5.5, 0.2), (12.0, 0.2), (30.0, 0.2)])  # leaves the grid
    counts, goal = demo_visitation(scene, UNIT_GRID)
    assert demo_goal_cell(scene, UNIT_GRID) == (0, 9)
    # (10, 10), one side cell of the diagonal step, then (9, 9) up to (0, 9).
    assert counts[0, 9] == 1 and counts.sum() == 12


def test_motion_features():
    grid = GridConfig(Extent(30.0, 10.0, 20.0, 20.0), rows=4, cols=4)
    m = motion_features(constant_velocity_scene(ego_speed=2.0), grid)
    assert m.shape == (3, 4, 4)
    assert np.all(m[0] == 2.0)
    np.testing.assert_allclose(m[1][:, 0], [25 / 40, 15 / 40, 5 / 40, -5 / 40])
    np.testing.assert_allclose(m[2][0], [15 / 40, 5 / 40, -5 / 40, -15 / 40])


def test_route_goal_point_lies_in_the_route_goal_cell():
    from rasterize.frames import grid_from_ego
    from rasterize.maps import route_goal_cell, route_goal_point
    from tests.scenes import UNIT_GRID, constant_velocity_scene

    scene = constant_velocity_scene()
    assert route_goal_point(scene, UNIT_GRID) is None                # no route
    routed = replace(scene, route_xy=np.array([[0.0, 0.0], [4.3, 0.2], [30.0, 0.0]]))
    point = route_goal_point(routed, UNIT_GRID)
    np.testing.assert_allclose(point, [4.3, 0.2], atol=1e-9)       # the last point inside
    assert tuple(grid_from_ego(point, UNIT_GRID)) == route_goal_cell(routed, UNIT_GRID)
