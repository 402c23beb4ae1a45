"""Round trips of the coordinate transforms (rasterize/frames.py): every frame change has an
inverse, within a tolerance that scales with the magnitudes involved (float64 keeps ~16 digits
of the largest of them)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rasterize.config import Extent, GridConfig, RasterConfig
from rasterize.frames import (
    box_corners,
    ego_from_grid,
    ego_from_pixel,
    ego_from_world,
    grid_from_ego,
    heading_angle,
    heading_from_highway_env,
    highway_env_from_world,
    in_grid,
    pixel_from_ego,
    rotation,
    world_from_ego,
    world_from_highway_env,
)

PROPERTY = settings(max_examples=200, deadline=None, derandomize=True, database=None)
EPS = np.finfo(np.float64).eps

metres = st.floats(-1e9, 1e9)
points = arrays(np.float64, st.tuples(st.integers(1, 8), st.just(2)), elements=metres)
angle = st.floats(-1e3, 1e3)


@st.composite
def divisions(draw, kind):
    extent = Extent(*(draw(st.floats(1e-2, 1e4)) for _ in range(4)))
    return kind(extent, rows=draw(st.integers(2, 500)), cols=draw(st.integers(2, 500)))


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _scale(*values):
    """The magnitude the rounding of a transform scales with."""
    return max(1.0, *(float(np.abs(v).max()) for v in values))


@PROPERTY
@given(pts=points, origin=arrays(np.float64, 2, elements=metres), heading=angle)
def test_world_and_ego_frames_round_trip(pts, origin, heading):
    tol = 64 * EPS * _scale(pts, origin)
    ego = ego_from_world(pts, origin, heading)
    np.testing.assert_allclose(world_from_ego(ego, origin, heading), pts, rtol=0, atol=tol)
    np.testing.assert_allclose(ego_from_world(world_from_ego(pts, origin, heading), origin, heading),
                               pts, rtol=0, atol=tol)
    # A rigid motion: distances to the origin survive it.
    np.testing.assert_allclose(np.linalg.norm(ego, axis=-1), np.linalg.norm(pts - origin, axis=-1),
                               rtol=0, atol=tol)


@PROPERTY
@given(origin=arrays(np.float64, 2, elements=metres), heading=angle, ahead=st.floats(1e-3, 1e4))
def test_ahead_of_the_pose_is_plus_x_in_the_ego_frame(origin, heading, ahead):
    point = origin + ahead * np.array([np.cos(heading), np.sin(heading)])
    x, y = ego_from_world(point, origin, heading)
    tol = 64 * EPS * _scale(origin, ahead)
    assert abs(x - ahead) <= tol and abs(y) <= tol


@PROPERTY
@given(pts=points, division=st.one_of(divisions(RasterConfig), divisions(GridConfig)))
def test_pixel_and_ego_frames_round_trip(pts, division):
    px = pixel_from_ego(pts, division)
    ext = division.extent
    tol = 64 * EPS * _scale(pts, ext.front_m, ext.left_m)
    np.testing.assert_allclose(ego_from_pixel(px, division), pts, rtol=0, atol=tol)
    # and the other way, in pixels: the same metres of rounding over the pixel size
    np.testing.assert_allclose(pixel_from_ego(ego_from_pixel(px, division), division), px, rtol=0,
                               atol=tol / min(division.row_m, division.col_m))


@PROPERTY
@given(grid=divisions(GridConfig), cells=arrays(np.int64, st.tuples(st.integers(1, 8), st.just(2)),
                                                elements=st.integers(-10_000, 10_000)))
def test_cell_centres_map_back_to_their_cells(grid, cells):
    np.testing.assert_array_equal(grid_from_ego(ego_from_grid(cells, grid), grid), cells)


@PROPERTY
@given(grid=divisions(GridConfig), pts=points)
def test_a_point_lies_within_half_a_cell_of_its_cells_centre(grid, pts):
    cells = grid_from_ego(pts, grid)
    offset = np.abs(ego_from_grid(cells, grid) - pts)
    # Flooring may land a point that rounding puts on an edge in either neighbour.
    tol = 64 * EPS * _scale(pts, grid.extent.front_m, grid.extent.left_m)
    assert (offset[..., 0] <= 0.5 * grid.row_m + tol).all()
    assert (offset[..., 1] <= 0.5 * grid.col_m + tol).all()
    inside = (pts[..., 0] < grid.extent.front_m - tol) & (pts[..., 0] > -grid.extent.back_m + tol) \
        & (pts[..., 1] < grid.extent.left_m - tol) & (pts[..., 1] > -grid.extent.right_m + tol)
    assert (in_grid(cells, grid)[inside]).all()


@PROPERTY
@given(pts=points)
def test_the_highway_env_flip_is_its_own_inverse(pts):
    np.testing.assert_array_equal(highway_env_from_world(world_from_highway_env(pts)), pts)
    np.testing.assert_array_equal(world_from_highway_env(highway_env_from_world(pts)), pts)
    original = pts.copy()
    world_from_highway_env(pts)
    np.testing.assert_array_equal(pts, original)         # a copy, the input untouched


@PROPERTY
@given(heading=st.floats(-1e3, 1e3))
def test_highway_env_headings_turn_with_the_flip(heading):
    """A highway-env heading and its direction vector give the same world heading."""
    direction = world_from_highway_env([np.cos(heading), np.sin(heading)])
    world = heading_from_highway_env(heading)
    assert abs(_wrap(heading_angle(direction) - world)) <= 1e-9 * max(1.0, abs(heading))
    assert heading_from_highway_env(heading_from_highway_env(heading)) == heading


@PROPERTY
@given(a=angle, length=st.floats(1e-3, 1e6))
def test_heading_angle_inverts_rotation(a, length):
    vector = rotation(a) @ [length, 0.0]
    assert abs(_wrap(heading_angle(vector) - a)) <= 1e-9 * max(1.0, abs(a))
    np.testing.assert_allclose(rotation(a) @ rotation(-a), np.eye(2), rtol=0, atol=1e-15)


@PROPERTY
@given(centre=arrays(np.float64, 2, elements=st.floats(-1e6, 1e6)), a=angle,
       length=st.floats(1e-2, 50.0), width=st.floats(1e-2, 5.0), norm=st.floats(1e-6, 1e6))
def test_box_corners_form_the_box(centre, a, length, width, norm):
    """Corners in the box's own frame: front-left, front-right, rear-right, rear-left, whatever
    the length of the heading vector."""
    corners = box_corners(centre, norm * np.array([np.cos(a), np.sin(a)]), length, width)
    local = ego_from_world(corners, centre, a)
    expected = 0.5 * np.array([[length, width], [length, -width], [-length, -width], [-length, width]])
    np.testing.assert_allclose(local, expected, rtol=0, atol=1e-9 * _scale(centre, length))
