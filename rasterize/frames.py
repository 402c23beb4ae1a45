"""Every coordinate transform of the toolkit, in one place.

Frames:
    world     right-handed, x east, y north, metres (simulator adapters convert into it).
    ego       origin at the ego's centre, x forward, y to the ego's left, metres.
    pixel     continuous raster coordinates (col, row): pixel (r, c) covers [c, c+1) x [r, r+1);
              row 0 is the front edge, col 0 the left edge.
    grid      integer risk-map cells (row, col), same orientation as pixels; "up" = row - 1 =
              forward.
    highway   highway-env's own frame: x east, y pointing *down* the screen (left-handed).
"""

from __future__ import annotations

import numpy as np

from rasterize.config import GridConfig, RasterConfig, _Division


def rotation(angle: float) -> np.ndarray:
    """2x2 counter-clockwise rotation matrix."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def ego_from_world(points: np.ndarray, origin: np.ndarray, heading: float) -> np.ndarray:
    """World points [..., 2] into the frame of a pose at `origin` facing `heading` (rad)."""
    return (np.asarray(points, dtype=np.float64) - origin) @ rotation(heading)


def world_from_ego(points: np.ndarray, origin: np.ndarray, heading: float) -> np.ndarray:
    return np.asarray(points, dtype=np.float64) @ rotation(heading).T + origin


def heading_angle(heading_xy: np.ndarray) -> np.ndarray:
    """Angle (rad) of heading vectors [..., 2]."""
    heading_xy = np.asarray(heading_xy)
    return np.arctan2(heading_xy[..., 1], heading_xy[..., 0])


def pixel_from_ego(points: np.ndarray, division: _Division) -> np.ndarray:
    """Ego points [..., 2] (x fwd, y left) into continuous (col, row) coordinates [..., 2]."""
    points = np.asarray(points, dtype=np.float64)
    ext = division.extent
    col = (ext.left_m - points[..., 1]) / division.col_m
    row = (ext.front_m - points[..., 0]) / division.row_m
    return np.stack([col, row], axis=-1)


def ego_from_pixel(colrow: np.ndarray, division: _Division) -> np.ndarray:
    colrow = np.asarray(colrow, dtype=np.float64)
    ext = division.extent
    x = ext.front_m - colrow[..., 1] * division.row_m
    y = ext.left_m - colrow[..., 0] * division.col_m
    return np.stack([x, y], axis=-1)


def grid_from_ego(points: np.ndarray, grid: GridConfig) -> np.ndarray:
    """Ego points [..., 2] into integer cells (row, col) [..., 2]; may fall outside the grid."""
    colrow = np.floor(pixel_from_ego(points, grid)).astype(np.int64)
    return colrow[..., ::-1]


def ego_from_grid(cells: np.ndarray, grid: GridConfig) -> np.ndarray:
    """Cell centres (row, col) [..., 2] into ego points [..., 2]."""
    cells = np.asarray(cells, dtype=np.float64)
    return ego_from_pixel(cells[..., ::-1] + 0.5, grid)


def in_grid(cells: np.ndarray, division: _Division) -> np.ndarray:
    """Mask [...] of (row, col) cells that lie inside the grid."""
    cells = np.asarray(cells)
    return ((cells[..., 0] >= 0) & (cells[..., 0] < division.rows)
            & (cells[..., 1] >= 0) & (cells[..., 1] < division.cols))


def cell_centres_ego(grid: GridConfig) -> np.ndarray:
    """Ego coordinates of every cell centre, [rows, cols, 2]."""
    rows, cols = np.meshgrid(np.arange(grid.rows), np.arange(grid.cols), indexing="ij")
    return ego_from_grid(np.stack([rows, cols], axis=-1), grid)


def world_from_highway_env(xy: np.ndarray) -> np.ndarray:
    """highway-env positions [..., 2] (y down) into the right-handed world frame (y up)."""
    xy = np.array(xy, dtype=np.float64)
    xy[..., 1] *= -1.0
    return xy


def highway_env_from_world(xy: np.ndarray) -> np.ndarray:
    return world_from_highway_env(xy)  # the flip is its own inverse


def heading_from_highway_env(heading: np.ndarray) -> np.ndarray:
    """highway-env headings (rad, clockwise on screen) into world headings (counter-clockwise)."""
    return -np.asarray(heading, dtype=np.float64)


def box_corners(center: np.ndarray, heading_xy: np.ndarray, length: float, width: float) -> np.ndarray:
    """Corners [4, 2] of an oriented box (front-left, front-right, rear-right, rear-left)."""
    fwd = np.asarray(heading_xy, dtype=np.float64)
    fwd = fwd / max(np.linalg.norm(fwd), 1e-12)
    left = np.array([-fwd[1], fwd[0]])
    hl, hw = 0.5 * length * fwd, 0.5 * width * left
    c = np.asarray(center, dtype=np.float64)
    return np.stack([c + hl + hw, c + hl - hw, c - hl - hw, c - hl + hw])


def ego_pose(scene) -> tuple[np.ndarray, float]:
    """The ego's current (origin [2], heading rad) in the world frame."""
    state = scene.ego_state()
    return state[:2].copy(), float(np.arctan2(state[3], state[2]))


__all__ = [
    "RasterConfig", "GridConfig", "rotation", "ego_from_world", "world_from_ego", "heading_angle",
    "pixel_from_ego", "ego_from_pixel", "grid_from_ego", "ego_from_grid", "in_grid",
    "cell_centres_ego", "world_from_highway_env", "highway_env_from_world",
    "heading_from_highway_env", "box_corners", "ego_pose",
]
