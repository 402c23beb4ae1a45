"""The grid-resolution maps the planner needs, each a pure function of a Scene and a GridConfig.

Shapes: every map is [rows, cols] float32 (motion features [3, rows, cols]); cells are (row, col)
with row 0 the front edge of the grid (see `rasterize.frames`).
"""

from __future__ import annotations

import numpy as np

from rasterize.config import GridConfig
from rasterize.errors import InputError
from rasterize.frames import (
    cell_centres_ego,
    ego_from_grid,
    ego_from_world,
    ego_pose,
    grid_from_ego,
    heading_angle,
    in_grid,
)
from rasterize.scene import Scene

# Sub-samples per cell side when averaging a Gaussian over a cell: highway cells are 4.8 m long,
# longer than the 1.5 m sigma, so a value at the cell centre alone could miss an agent entirely.
_SUBSAMPLES = 5


# The route is checked at points this far apart (m), in training and in closed loop alike; a
# sample holds at most ROUTE_POINTS of them (256 m: more than any grid's reach ahead).
ROUTE_STEP_M = 1.0
ROUTE_POINTS = 256


def _subcell_offsets(grid: GridConfig) -> np.ndarray:
    """Ego-frame offsets [S, 2] of the sub-sample points within a cell, about its centre."""
    u = (np.arange(_SUBSAMPLES) + 0.5) / _SUBSAMPLES - 0.5
    dx, dy = np.meshgrid(u * grid.row_m, u * grid.col_m, indexing="ij")
    return np.stack([dx.ravel(), dy.ravel()], axis=-1)


def uncertainty_map(scene: Scene, grid: GridConfig, sigma_x: float = 0.5,
                    sigma_y: float = 1.5) -> np.ndarray:
    """Positional uncertainty of the ado agents now, [rows, cols] in [0, 1].

    Each ado agent is an unnormalised bivariate Gaussian (peak 1) centred on it: `sigma_y` metres
    along its heading and `sigma_x` across it, so the default 0.5 / 1.5 is a car-shaped oval (the
    image axes of the planner paper: x across, y along an agent aligned with the ego). Agents
    combine by maximum; each cell holds the mean over its area.
    """
    if not (sigma_x > 0 and sigma_y > 0):
        raise InputError(f"uncertainty sigmas must be positive metres, got {sigma_x}, {sigma_y}")
    origin, heading = ego_pose(scene)
    now = scene.current_index
    ados = [a for a in np.flatnonzero(scene.valid[:, now]) if a != scene.ego_index]
    centres = ego_from_world(scene.states[ados, now, :2], origin, heading).reshape(-1, 2)
    headings = np.array([heading_angle(scene.states[a, now, 2:4]) - heading for a in ados])
    return footprint_map(centres, headings, grid, sigma_x, sigma_y)


def footprint_map(centres: np.ndarray, headings: np.ndarray, grid: GridConfig,
                  sigma_x: float = 0.5, sigma_y: float = 1.5) -> np.ndarray:
    """[rows, cols] in [0, 1]: agents at ego-frame `centres` [M, 2] heading `headings` [M] (rad,
    ego frame), each an unnormalised Gaussian (peak 1) `sigma_y` m along its heading and
    `sigma_x` across, combined by maximum, each cell the mean over its area (`uncertainty_map`'s
    shape, wherever the agents are: now, predicted or recorded)."""
    centres = np.asarray(centres, float).reshape(-1, 2)
    return footprint_maps(centres, headings, np.zeros(len(centres), int), 1, grid, sigma_x,
                          sigma_y)[0]


def footprint_maps(centres: np.ndarray, headings: np.ndarray, layer: np.ndarray, layers: int,
                   grid: GridConfig, sigma_x: float = 0.5, sigma_y: float = 1.5) -> np.ndarray:
    """[layers, rows, cols]: `footprint_map` of the agents [M] of each layer (`layer` [M] in
    0 … layers − 1, e.g. a time step), all drawn in one pass."""
    centres = np.asarray(centres, float).reshape(-1, 2)
    headings = np.asarray(headings, float).reshape(-1)
    offsets = _subcell_offsets(grid).astype(np.float32)                      # [S, 2]
    # float32 throughout: the maps are float32 and 1e-7 of a peak of 1 is far below what the
    # 4-sigma cut below leaves out (e^-8 = 3e-4); the exponentials are most of the time.
    maps = np.zeros((layers, grid.rows, grid.cols), np.float32)
    if not len(centres):
        return maps
    # Only points within 4 sigma of an agent can hold more than e^-8 of it: each agent is drawn on
    # the cells that hold a sub-sample point inside the bounding box of its 4-sigma ellipse
    # (half sides 4 sqrt((sy cos h)^2 + (sx sin h)^2) along x and the same with sin/cos swapped
    # along y, plus a cell), those cells' rows and columns a rectangle. The box follows the
    # heading, so an agent along the ego's lane takes a third of the columns a square would.
    cos_h, sin_h = np.cos(headings), np.sin(headings)
    half = 4.0 * np.stack([np.hypot(sigma_y * cos_h, sigma_x * sin_h),
                           np.hypot(sigma_y * sin_h, sigma_x * cos_h)], axis=-1)          # [M, 2]
    half += [grid.row_m, grid.col_m]
    first = grid_from_ego(centres + half, grid)                              # [M, 2] top-left
    last = grid_from_ego(centres - half, grid)                               # bottom-right
    # Every agent's Gaussian on a patch of one size (the largest window) at once, so that the
    # exponentials are one array operation; cells outside an agent's own window are left out.
    size = (last - first).max(axis=0) + 1                                    # [2] rows, cols
    rows = first[:, 0, None] + np.arange(size[0])                            # [M, P]
    cols = first[:, 1, None] + np.arange(size[1])                            # [M, Q]
    cell_x = ego_from_grid(np.stack([rows, np.zeros_like(rows)], -1), grid)[..., 0]   # [M, P]
    cell_y = ego_from_grid(np.stack([np.zeros_like(cols), cols], -1), grid)[..., 1]   # [M, Q]
    rel_x = (cell_x - centres[:, 0, None]).astype(np.float32)                # [M, P]
    rel_y = (cell_y - centres[:, 1, None]).astype(np.float32)                # [M, Q]
    dx = rel_x[:, :, None, None] + offsets[:, 0]                             # [M, P, 1, S]
    dy = rel_y[:, None, :, None] + offsets[:, 1]                             # [M, 1, Q, S]
    cos = (cos_h / sigma_y).astype(np.float32)[:, None, None, None]
    sin = (sin_h / sigma_y).astype(np.float32)[:, None, None, None]
    cos_x = (cos_h / sigma_x).astype(np.float32)[:, None, None, None]
    sin_x = (sin_h / sigma_x).astype(np.float32)[:, None, None, None]
    along = dx * cos + dy * sin                                              # in sigmas
    across = dy * cos_x - dx * sin_x
    patches = np.exp(np.float32(-0.5) * (along * along + across * across))  # [M, P, Q, S]
    # The patch cells inside both the agent's own window and the grid, as flat cell numbers
    # (layer, row, col). Agents combine by maximum per sub-sample point, then each cell is the
    # mean over its sub-samples: a cell one agent alone covers is the mean of its patch there; a
    # cell several cover (rare: agents of one layer close together), the mean of their maximum.
    # Only covered cells are written: the rest stay 0, as a maximum with nothing leaves them.
    keep_rows = (rows >= 0) & (rows < grid.rows) & (rows <= last[:, :1])   # [M, P]
    keep_cols = (cols >= 0) & (cols < grid.cols) & (cols <= last[:, 1:])   # [M, Q]
    keep = keep_rows[:, :, None] & keep_cols[:, None, :]                     # [M, P, Q]
    layer = np.asarray(layer).reshape(-1)
    cell = ((layer[:, None, None] * grid.rows + rows[:, :, None]) * grid.cols
            + cols[:, None, :])[keep]                                        # [N]
    if not len(cell):
        return maps
    points = patches[keep]                                                   # [N, S]
    flat = maps.reshape(-1)
    flat[cell] = points.mean(axis=1)
    order = np.argsort(cell, kind="stable")
    ordered = cell[order]
    new_cell = np.concatenate([[True], ordered[1:] != ordered[:-1], [True]])   # [N + 1]
    if not new_cell.all():
        bounds = np.flatnonzero(new_cell)                                    # group starts, N
        shared = np.flatnonzero(np.diff(bounds) > 1)
        stack = points[order]
        for start, end in zip(bounds[shared], bounds[shared + 1]):
            flat[ordered[start]] = stack[start:end].max(axis=0).mean()
    return maps


def goal_map(goal_cell: tuple[int, int], grid: GridConfig, variance: float = 5.0) -> np.ndarray:
    """Gaussian (peak 1) around `goal_cell` (row, col), variance in cells squared, [rows, cols]."""
    if not variance > 0:
        raise InputError(f"goal variance must be positive (cells^2), got {variance}")
    rows, cols = np.meshgrid(np.arange(grid.rows), np.arange(grid.cols), indexing="ij")
    d2 = (rows - goal_cell[0]) ** 2 + (cols - goal_cell[1]) ** 2
    return np.exp(-0.5 * d2 / variance).astype(np.float32)


def _densify(points_ego: np.ndarray, grid: GridConfig) -> list[tuple[int, int]]:
    """Cells a polyline passes through, as a 4-connected path, stopping where it leaves the grid."""
    step = 0.25 * min(grid.row_m, grid.col_m)
    pieces = []
    for a, b in zip(points_ego[:-1], points_ego[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        pieces.append(a + np.linspace(0.0, 1.0, n + 1)[:-1, None] * (b - a))
    samples = np.concatenate(pieces + [points_ego[-1:]])
    cells = grid_from_ego(samples, grid)
    outside = np.flatnonzero(~in_grid(cells, grid))
    if outside.size:
        samples, cells = samples[: outside[0]], cells[: outside[0]]
    changed = np.concatenate([[True], (np.diff(cells, axis=0) != 0).any(axis=1)])
    path: list[tuple[int, int]] = []
    for point, cell in zip(samples[changed], cells[changed]):
        cell = (int(cell[0]), int(cell[1]))
        if path and abs(cell[0] - path[-1][0]) + abs(cell[1] - path[-1][1]) > 1:
            # A diagonal step (the segment crossed a cell corner): go through whichever of the
            # two side cells is nearer the point, keeping the path 4-connected.
            r0, c0 = path[-1]
            options = [(cell[0], c0), (r0, cell[1])]
            path.append(min(options, key=lambda rc: np.linalg.norm(ego_from_grid(rc, grid) - point)))
        path.append(cell)
    return path


def demo_path_cells(scene: Scene, grid: GridConfig) -> list[tuple[int, int]]:
    """The ego's recorded future as a 4-connected cell path from its own cell (see `_densify`)."""
    origin, heading = ego_pose(scene)
    future = scene.ego_future_xy()
    points = np.concatenate([[[0.0, 0.0]], ego_from_world(future, origin, heading)], axis=0)
    return _densify(points, grid)


def demo_visitation(scene: Scene, grid: GridConfig) -> tuple[np.ndarray, np.ndarray]:
    """D_demo of the ego's recorded future: (visit counts [rows, cols], goal one-hot [rows, cols]).

    The path starts at the ego's cell, follows its future waypoints densified to a 4-connected
    cell path, and ends at the last cell inside the grid, where the goal one-hot sits (the
    planner's `end` action).
    """
    return visitation_from_path(demo_path_cells(scene, grid), grid)


def visitation_from_path(path: list[tuple[int, int]], grid: GridConfig
                         ) -> tuple[np.ndarray, np.ndarray]:
    """(visit counts, goal one-hot at the path's last cell), each [rows, cols]."""
    counts = np.zeros((grid.rows, grid.cols), dtype=np.float32)
    goal = np.zeros_like(counts)
    for r, c in path:
        counts[r, c] += 1.0
    goal[path[-1]] = 1.0
    return counts, goal


def demo_goal_cell(scene: Scene, grid: GridConfig) -> tuple[int, int]:
    """The goal of a demonstration: the last in-grid cell of its densified future path."""
    _, goal = demo_visitation(scene, grid)
    r, c = np.argwhere(goal)[0]
    return int(r), int(c)


def _route_to_goal(scene: Scene, grid: GridConfig) -> np.ndarray | None:
    """[K, 2] ego-frame points (metres) of the ego's route up to its last point inside the grid,
    or None without a route or with none of it inside: what the goal rules below all read."""
    if scene.route_xy is None:
        return None
    origin, heading = ego_pose(scene)
    points = ego_from_world(scene.route_xy, origin, heading)
    inside = np.flatnonzero(in_grid(grid_from_ego(points, grid), grid))
    return points[: inside[-1] + 1] if inside.size else None


def route_goal_point(scene: Scene, grid: GridConfig) -> np.ndarray | None:
    """The ego-frame point [2] (metres) inside `route_goal_cell`: the last route point inside the
    grid, or None without a route or with none of it inside."""
    points = _route_to_goal(scene, grid)
    return None if points is None else points[-1]


def route_goal_cell(scene: Scene, grid: GridConfig) -> tuple[int, int]:
    """The planner's goal: the last point of the ego's route ahead that lies inside the grid.

    Without a route (`scene.route_xy` is None) this falls back to the demonstration's goal.
    """
    if scene.route_xy is None:
        return demo_goal_cell(scene, grid)
    goal = route_goal_point(scene, grid)
    if goal is None:
        return start_cell(grid)
    r, c = grid_from_ego(goal, grid)
    return int(r), int(c)


def route_cells(scene: Scene, grid: GridConfig) -> np.ndarray:
    """[ROUTE_POINTS, 2] cells (row, col) of points every ROUTE_STEP_M along the ego's route, from
    the ego (distance 0) to its last point inside the grid, padded with −1 (all −1 without a
    route or with none of it inside)."""
    out = np.full((ROUTE_POINTS, 2), -1, dtype=np.int64)
    points = _route_to_goal(scene, grid)
    if points is None:
        return out
    points = np.concatenate([np.zeros((1, 2)), points])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    along = np.append(np.arange(0.0, arc[-1], ROUTE_STEP_M), arc[-1])[:ROUTE_POINTS]
    dense = np.column_stack([np.interp(along, arc, points[:, 0]), np.interp(along, arc, points[:, 1])])
    out[: len(dense)] = np.clip(grid_from_ego(dense, grid), 0, [grid.rows - 1, grid.cols - 1])
    return out


def start_cell(grid: GridConfig) -> tuple[int, int]:
    """The ego's own cell (the ego sits at the ego-frame origin)."""
    r, c = grid_from_ego(np.zeros(2), grid)
    return int(r), int(c)


def motion_features(scene: Scene, grid: GridConfig) -> np.ndarray:
    """[3, rows, cols]: ego speed (m/s) everywhere, cell-centre x and y over the grid's extent.

    x is divided by the grid's length (front + back) and y by its width (left + right), so both
    stay within [-1, 1] whatever the extent.
    """
    centres = cell_centres_ego(grid)
    speed = float(scene.ego_state()[4])
    return np.stack([
        np.full((grid.rows, grid.cols), speed),
        centres[..., 0] / grid.extent.length_m,
        centres[..., 1] / grid.extent.width_m,
    ]).astype(np.float32)
