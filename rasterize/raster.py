"""The ego-centred BEV raster, drawn with OpenCV.

`rasterize_scene(scene, config)` returns uint8 [C, rows, cols] with the channels of `CHANNELS`
(255 = fully present). The ego faces up (row 0 is ahead), its left is column 0.
"""

from __future__ import annotations

import cv2
import numpy as np

from rasterize.config import RasterConfig
from rasterize.frames import ego_from_world, ego_pose, pixel_from_ego
from rasterize.scene import Lane, LineType, Scene

CHANNELS: tuple[str, ...] = (
    "drivable",        # union of lane areas
    "lane_solid",      # continuous painted lines
    "lane_dashed",     # dashed painted lines
    "lane_centre",     # lane centre lines
    "ego",             # ego box now
    "agents",          # other agents' boxes now
    "agents_history",  # other agents' boxes over the last history_s, fading with age
    "ego_history",     # ego's boxes over the last history_s, fading with age
)
CHANNEL_INDEX = {name: i for i, name in enumerate(CHANNELS)}

# Dash pattern of dashed lines, metres along the lane (highway-env draws 3 m stripes every ~7 m).
DASH_ON_M = 3.0
DASH_PERIOD_M = 7.33
# OpenCV draws with fixed-point vertices: 4 fractional bits keep sub-pixel accuracy.
_SHIFT = 4
_SCALE = 1 << _SHIFT


def _cv_points(colrow: np.ndarray) -> np.ndarray:
    """Continuous (col, row) into OpenCV's fixed-point pixel-centre convention."""
    return np.round((colrow - 0.5) * _SCALE).astype(np.int32)


def _shrink_box(corners: np.ndarray) -> np.ndarray:
    """Pull a box's edges in by half a pixel (see `_fill`); a box thinner than a pixel keeps a line.

    corners [4, 2] in pixel space, in order around the box (a parallelogram after scaling).
    """
    centre = corners.mean(axis=0)
    a = 0.5 * (corners[0] - corners[3])   # half-axis along the box's length
    b = 0.5 * (corners[0] - corners[1])   # half-axis along its width
    area = abs(a[0] * b[1] - a[1] * b[0])
    if area < 1e-12:
        return corners
    a2 = a * max(0.0, 1.0 - 0.5 * np.linalg.norm(b) / area)
    b2 = b * max(0.0, 1.0 - 0.5 * np.linalg.norm(a) / area)
    return np.stack([centre + a2 + b2, centre + a2 - b2, centre - a2 - b2, centre - a2 + b2])


def _shrink_strip(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pull the two sides of a lane strip [P, 2] towards each other by half a pixel each."""
    across = right - left
    norm = np.linalg.norm(across, axis=1, keepdims=True)
    step = np.minimum(0.5, 0.5 * norm) * across / np.maximum(norm, 1e-12)
    return left + step, right - step


def _fill(canvas: np.ndarray, polygon_colrow: np.ndarray, value: int) -> None:
    """Fill a polygon given in continuous (col, row) pixel coordinates.

    OpenCV paints every pixel whose centre lies within half a pixel of the polygon; callers pull
    edges in by half a pixel first (`_shrink_box`, `_shrink_strip`), so that a pixel is painted
    when its centre lies inside the shape, and a 4 m box on 1 m pixels covers exactly 4 pixels.
    """
    cv2.fillPoly(canvas, [_cv_points(polygon_colrow)], int(value), lineType=cv2.LINE_8, shift=_SHIFT)


def _polylines(canvas: np.ndarray, lines: list[np.ndarray], value: int = 255) -> None:
    if lines:
        cv2.polylines(canvas, [_cv_points(p) for p in lines], False, int(value), 1, cv2.LINE_8,
                      _SHIFT)


# Arc-length spacing (m) at which dashed boundaries are resampled before cutting into dashes.
_DASH_SAMPLE_M = 0.5


def _dashes(line: np.ndarray, start_s: float) -> list[np.ndarray]:
    """Cut a polyline [P, 2] into its painted dashes, phase anchored at the lane's arc length."""
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    s = start_s + np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] - s[0] < 1e-9:
        return []
    # Sample every _DASH_SAMPLE_M and at every dash end, then keep the painted runs.
    first = np.floor(s[0] / DASH_PERIOD_M) * DASH_PERIOD_M
    starts = np.arange(first, s[-1], DASH_PERIOD_M)
    knots = np.concatenate([np.arange(s[0], s[-1], _DASH_SAMPLE_M), starts, starts + DASH_ON_M,
                            [s[-1]]])
    knots = np.unique(knots[(knots >= s[0]) & (knots <= s[-1])])
    phase = np.mod(knots - first, DASH_PERIOD_M)
    painted = phase <= DASH_ON_M + 1e-9
    # A run starts where painting starts or where a new period begins (phase wraps to 0).
    new_run = painted & np.concatenate([[True], ~painted[:-1] | (phase[1:] < phase[:-1])])
    run_id = np.cumsum(new_run)
    pts = np.stack([np.interp(knots, s, line[:, 0]), np.interp(knots, s, line[:, 1])], axis=1)
    ids = run_id[painted]
    pts = pts[painted]
    cuts = np.flatnonzero(np.diff(ids)) + 1
    return [run for run in np.split(pts, cuts) if len(run) >= 2]


def _inside(colrow: np.ndarray, config: RasterConfig, margin: float = 2.0) -> np.ndarray:
    return ((colrow[:, 0] > -margin) & (colrow[:, 0] < config.cols + margin)
            & (colrow[:, 1] > -margin) & (colrow[:, 1] < config.rows + margin))


def _visible(colrow: np.ndarray, config: RasterConfig) -> bool:
    return bool(_inside(colrow, config).any())


def _draw_lane(layers: np.ndarray, lane: Lane, origin: np.ndarray, heading: float,
               config: RasterConfig) -> None:
    # One transform per polyline; everything below works in pixel coordinates.
    left, right, centre = (pixel_from_ego(ego_from_world(p, origin, heading), config)
                           for p in (lane.left, lane.right, lane.centre))
    if not (_visible(left, config) or _visible(right, config)
            or _visible(np.concatenate([left, right]).mean(axis=0, keepdims=True), config)):
        # Both sides outside: the lane may still cross the raster between far-apart samples.
        box = np.concatenate([left, right])
        if (box[:, 0].max() < 0 or box[:, 0].min() > config.cols or box[:, 1].max() < 0
                or box[:, 1].min() > config.rows):
            return
    in_left, in_right = _shrink_strip(left, right)
    _fill(layers[CHANNEL_INDEX["drivable"]], np.concatenate([in_left, in_right[::-1]]), 255)
    _polylines(layers[CHANNEL_INDEX["lane_centre"]], [centre])
    for boundary_world, boundary, line in ((lane.left, left, lane.left_line),
                                           (lane.right, right, lane.right_line)):
        if line in (LineType.SOLID, LineType.SOLID_THICK):
            _polylines(layers[CHANNEL_INDEX["lane_solid"]], [boundary])
        elif line == LineType.DASHED:
            # Dash lengths are metres along the lane: cut in the world, draw in pixels.
            dashes = _dashes(boundary_world, lane.start_s)
            if not dashes:
                continue
            px = pixel_from_ego(ego_from_world(np.concatenate(dashes), origin, heading), config)
            bounds = np.cumsum([0] + [len(d) for d in dashes])
            inside = _inside(px, config).astype(np.int64)
            shown = np.add.reduceat(inside, bounds[:-1]) > 0
            _polylines(layers[CHANNEL_INDEX["lane_dashed"]],
                       [px[a:b] for a, b, keep in zip(bounds[:-1], bounds[1:], shown) if keep])


def _boxes_px(scene: Scene, origin: np.ndarray, heading: float, config: RasterConfig
              ) -> np.ndarray:
    """Pixel corners [N, T, 4, 2] of every agent's box at every time step (one transform)."""
    states = scene.states
    fwd = states[..., 2:4] / np.maximum(np.linalg.norm(states[..., 2:4], axis=-1, keepdims=True),
                                        1e-12)
    left = np.stack([-fwd[..., 1], fwd[..., 0]], axis=-1)
    half_l = 0.5 * scene.sizes[:, None, None, 0:1] * fwd[..., None, :]
    half_w = 0.5 * scene.sizes[:, None, None, 1:2] * left[..., None, :]
    signs_l = np.array([1, 1, -1, -1])[:, None]
    signs_w = np.array([1, -1, -1, 1])[:, None]
    corners = states[..., None, 0:2] + signs_l * half_l + signs_w * half_w   # [N, T, 4, 2]
    return pixel_from_ego(ego_from_world(corners, origin, heading), config)


def history_intensity(age_s: float, history_s: float, dt: float) -> int:
    """Brightness of a box drawn `age_s` seconds ago: fades linearly, the oldest still visible."""
    return int(round(255 * (1.0 - age_s / (history_s + dt))))


def rasterize_scene(scene: Scene, config: RasterConfig) -> np.ndarray:
    """The BEV raster uint8 [len(CHANNELS), rows, cols] of the scene at its current time."""
    layers = np.zeros((len(CHANNELS), config.rows, config.cols), dtype=np.uint8)
    origin, heading = ego_pose(scene)
    for lane in scene.lanes:
        _draw_lane(layers, lane, origin, heading, config)

    now, ego = scene.current_index, scene.ego_index
    oldest = max(0, now - int(round(config.history_s / scene.dt)))
    boxes = _boxes_px(scene, origin, heading, config)
    for step in range(oldest, now + 1):  # oldest first: newer, brighter boxes overwrite
        age = (now - step) * scene.dt
        value = history_intensity(age, config.history_s, scene.dt)
        for agent in np.flatnonzero(scene.valid[:, step]):
            is_ego = agent == ego
            if step == now:
                channel = "ego" if is_ego else "agents"
                value = 255
            else:
                channel = "ego_history" if is_ego else "agents_history"
            _fill(layers[CHANNEL_INDEX[channel]], _shrink_box(boxes[agent, step]), value)
    return layers
