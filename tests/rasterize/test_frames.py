import numpy as np
import pytest

from rasterize.config import Extent, GridConfig
from rasterize.frames import (
    box_corners,
    ego_from_grid,
    ego_from_world,
    grid_from_ego,
    heading_from_highway_env,
    pixel_from_ego,
    world_from_ego,
    world_from_highway_env,
)
from tests.scenes import UNIT_GRID, UNIT_RASTER


def test_ego_from_world_hand_computed():
    # Ego at (10, 5) facing north: a point 3 m further north is 3 m ahead; one 2 m west is 2 m left.
    origin, heading = np.array([10.0, 5.0]), np.pi / 2
    pts = np.array([[10.0, 8.0], [8.0, 5.0], [11.0, 5.0]])
    np.testing.assert_allclose(ego_from_world(pts, origin, heading),
                               [[3.0, 0.0], [0.0, 2.0], [0.0, -1.0]], atol=1e-12)


def test_world_from_ego_inverts():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(50, 2)) * 30
    origin, heading = rng.normal(size=2) * 100, 2.3
    np.testing.assert_allclose(world_from_ego(ego_from_world(pts, origin, heading), origin, heading),
                               pts, atol=1e-9)


def test_pixel_and_grid_hand_computed():
    # 1 m cells, 10 m each way: the ego's centre is the corner between pixels 9 and 10.
    np.testing.assert_allclose(pixel_from_ego([0.0, 0.0], UNIT_RASTER), [10.0, 10.0])
    np.testing.assert_allclose(pixel_from_ego([9.5, 9.5], UNIT_RASTER), [0.5, 0.5])  # front-left
    np.testing.assert_array_equal(grid_from_ego([9.5, 9.5], UNIT_GRID), [0, 0])
    np.testing.assert_array_equal(grid_from_ego([-9.5, -9.5], UNIT_GRID), [19, 19])
    np.testing.assert_array_equal(grid_from_ego([0.1, 0.1], UNIT_GRID), [9, 9])
    np.testing.assert_allclose(ego_from_grid([0, 0], UNIT_GRID), [9.5, 9.5])


def test_non_square_cells():
    grid = GridConfig(Extent(200.0, 40.0, 20.0, 20.0), rows=50, cols=50)
    assert grid.row_m == pytest.approx(4.8) and grid.col_m == pytest.approx(0.8)
    # 100 m ahead, 4 m right: row (200 - 100) / 4.8 = 20.8 -> 20; col (20 + 4) / 0.8 = 30
    np.testing.assert_array_equal(grid_from_ego([100.0, -4.0], grid), [20, 30])


def test_highway_env_flip():
    # highway-env's y points down the screen: a lane at y = 4 there is 4 m *south* here.
    np.testing.assert_allclose(world_from_highway_env([3.0, 4.0]), [3.0, -4.0])
    assert heading_from_highway_env(0.3) == pytest.approx(-0.3)


def test_box_corners():
    c = box_corners([1.0, 1.0], [0.0, 1.0], length=4.0, width=2.0)  # facing north
    np.testing.assert_allclose(c, [[0.0, 3.0], [2.0, 3.0], [2.0, -1.0], [0.0, -1.0]], atol=1e-12)
