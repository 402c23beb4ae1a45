"""Maps per future step for the space-time planner (DESIGN §3b), each on the risk-map grid.

Step t = 1 … T lies t · step_s seconds after the present. Shapes: per-step maps [T, rows, cols]
float32 in [0, 1]; evidence [T, EVIDENCE_CHANNELS, rows, cols]; demonstration cells [T, 2]
(row, col), −1 where the human is off the grid.

What the planner sees (`step_evidence`, present information only, as the raster's
`--predict-s` channels but one map per step instead of one faded summary):
    predicted   the other agents' footprints at step t, constant speed along their lanes
                (`rasterize.predict.predict_along_lanes`), the same Gaussian shape as the
                uncertainty map
    red         the stop lines whose light is red at step t (the recording's signal plan; a
                signal's state ahead is what a driver reads off the light and its cycle)
What training alone reads (the recorded future, never an input): `future_footprints` (N_t of the
IRL loss) and `demo_cells_per_step` (D_demo_t).
"""

from __future__ import annotations

import numpy as np

from rasterize.config import GridConfig
from rasterize.errors import InputError
from rasterize.frames import ego_from_world, ego_pose, grid_from_ego, in_grid
from rasterize.maps import footprint_maps
from rasterize.predict import predict_along_lanes
from rasterize.scene import Scene

EVIDENCE_CHANNELS = ("predicted", "red")
# Points a stop line is sampled at per cell side, so that a line never slips between cells.
_STOP_LINE_SAMPLES_PER_CELL = 4


def quantised(maps: np.ndarray) -> np.ndarray:
    """`maps` in [0, 1] as uint8 (255 = 1): how samples store per-step maps (a twelfth of the
    space) and so how the planner must see them too, to the same 1/255."""
    return np.round(np.clip(maps, 0.0, 1.0) * 255.0).astype(np.uint8)


def step_times(steps: int, step_s: float) -> np.ndarray:
    """Seconds ahead of each step [T]: step_s, 2 step_s, …, steps · step_s."""
    if steps < 1 or not step_s > 0:
        raise InputError(f"space-time steps {steps} and step {step_s} s must be positive")
    return step_s * np.arange(1, steps + 1)


def predicted_footprints(scene: Scene, grid: GridConfig, steps: int, step_s: float,
                         sigma_x: float = 0.5, sigma_y: float = 1.5) -> np.ndarray:
    """[T, rows, cols]: where the other agents are predicted at each step, from the present only."""
    origin, heading = ego_pose(scene)
    xy, fwd = predict_along_lanes(scene, steps * step_s, step_s)           # [N, T, 2] world
    now = scene.current_index
    others = scene.valid[:, now].copy()
    others[scene.ego_index] = False
    xy, fwd = xy[others].reshape(-1, 2), fwd[others].reshape(-1, 2)       # agent-major [M T, 2]
    centres = ego_from_world(xy, origin, heading)
    headings = np.arctan2(fwd[:, 1], fwd[:, 0]) - heading
    layer = np.tile(np.arange(steps), int(others.sum()))
    return footprint_maps(centres, headings, layer, steps, grid, sigma_x, sigma_y)


def red_stop_lines(scene: Scene, grid: GridConfig, steps: int, step_s: float) -> np.ndarray:
    """[T, rows, cols]: 1 on the cells of every stop line whose light is red at step t."""
    maps = np.zeros((steps, grid.rows, grid.cols), np.float32)
    if not scene.signals:
        return maps
    origin, heading = ego_pose(scene)
    times = step_times(steps, step_s)
    for signal in scene.signals:
        a, b = ego_from_world(signal.stop_line, origin, heading)
        count = max(2, int(np.ceil(np.linalg.norm(b - a) / min(grid.row_m, grid.col_m)
                                   * _STOP_LINE_SAMPLES_PER_CELL)))
        cells = grid_from_ego(a + np.linspace(0.0, 1.0, count)[:, None] * (b - a), grid)
        cells = cells[in_grid(cells, grid)]
        if not len(cells):
            continue
        for t, time_s in enumerate(times):
            if signal.red_at(float(time_s)):
                maps[t, cells[:, 0], cells[:, 1]] = 1.0
    return maps


def step_evidence(scene: Scene, grid: GridConfig, steps: int, step_s: float,
                  sigma_x: float = 0.5, sigma_y: float = 1.5) -> np.ndarray:
    """[T, len(EVIDENCE_CHANNELS), rows, cols] float32: what the planner sees of each step ahead.
    Reads the present only (`scene.past()` gives the same maps)."""
    scene = scene.past()
    return np.stack([predicted_footprints(scene, grid, steps, step_s, sigma_x, sigma_y),
                     red_stop_lines(scene, grid, steps, step_s)], axis=1)


def _future_index(scene: Scene, steps: int, step_s: float) -> np.ndarray:
    """Time indices [T] of the steps in the scene's arrays; InputError if the recording is too
    short or its time step does not divide step_s."""
    stride = step_s / scene.dt
    if abs(stride - round(stride)) > 1e-6:
        raise InputError(f"scene time step {scene.dt} s does not divide the space-time step "
                         f"{step_s} s; resample the recording")
    index = scene.current_index + round(stride) * np.arange(1, steps + 1)
    if index[-1] >= scene.num_steps:
        raise InputError(f"scene holds {scene.num_future_steps * scene.dt:g} s of future, the "
                         f"space-time planner needs {steps * step_s:g} s; collect longer windows")
    return index


def future_footprints(scene: Scene, grid: GridConfig, steps: int, step_s: float,
                      sigma_x: float = 0.5, sigma_y: float = 1.5) -> np.ndarray:
    """[T, rows, cols]: N_t, the other agents' footprints at their *recorded* positions at each
    step (training signal only: the IRL loss lowers reward where the policy would meet them)."""
    origin, heading = ego_pose(scene)
    index = _future_index(scene, steps, step_s)
    present = scene.valid[:, index].copy()                                    # [N, T]
    present[scene.ego_index] = False
    agent, step = np.nonzero(present)
    states = scene.states[agent, index[step]]                                 # [M, 6]
    centres = ego_from_world(states[:, :2], origin, heading).reshape(-1, 2)
    headings = np.arctan2(states[:, 3], states[:, 2]) - heading
    return footprint_maps(centres, headings, step, steps, grid, sigma_x, sigma_y)


def demo_cells_per_step(scene: Scene, grid: GridConfig, steps: int, step_s: float) -> np.ndarray:
    """[T, 2] int64: the human's cell at each step (D_demo_t is one-hot there); −1 at steps where
    the human is off the grid or unrecorded."""
    index = _future_index(scene, steps, step_s)
    origin, heading = ego_pose(scene)
    cells = grid_from_ego(ego_from_world(scene.states[scene.ego_index, index, :2], origin, heading),
                          grid)
    keep = in_grid(cells, grid) & scene.valid[scene.ego_index, index]
    return np.where(keep[:, None], cells, -1).astype(np.int64)
