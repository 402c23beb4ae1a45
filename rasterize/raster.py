"""The ego-centred BEV raster, drawn with OpenCV.

`rasterize_scene(scene, config)` returns uint8 [C, rows, cols] with the channels of `CHANNELS`
(255 = fully present). The ego faces up (row 0 is ahead), its left is column 0.
"""

from __future__ import annotations

import cv2
import numpy as np

from rasterize.config import RasterConfig
from rasterize.frames import box_corners, ego_from_world, ego_pose, pixel_from_ego
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


def _polyline(canvas: np.ndarray, colrow: np.ndarray, value: int = 255) -> None:
    cv2.polylines(canvas, [_cv_points(colrow)], False, int(value), 1, cv2.LINE_8, _SHIFT)


def _dashes(line_ego: np.ndarray, start_s: float) -> list[np.ndarray]:
    """Split a polyline [P, 2] into its painted dashes, phase anchored at the lane's arc length."""
    seg = np.linalg.norm(np.diff(line_ego, axis=0), axis=1)
    s = start_s + np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= s[0]:
        return []
    first = np.floor(s[0] / DASH_PERIOD_M) * DASH_PERIOD_M
    dashes = []
    for a in np.arange(first, s[-1], DASH_PERIOD_M):
        lo, hi = max(a, s[0]), min(a + DASH_ON_M, s[-1])
        if hi <= lo:
            continue
        inner = (s > lo) & (s < hi)
        pts = np.concatenate([
            [[np.interp(lo, s, line_ego[:, 0]), np.interp(lo, s, line_ego[:, 1])]],
            line_ego[inner],
            [[np.interp(hi, s, line_ego[:, 0]), np.interp(hi, s, line_ego[:, 1])]],
        ])
        dashes.append(pts)
    return dashes


def _draw_lane(layers: np.ndarray, lane: Lane, origin: np.ndarray, heading: float,
               config: RasterConfig) -> None:
    to_px = lambda pts: pixel_from_ego(ego_from_world(pts, origin, heading), config)  # noqa: E731
    left, right = _shrink_strip(to_px(lane.left), to_px(lane.right))
    _fill(layers[CHANNEL_INDEX["drivable"]], np.concatenate([left, right[::-1]]), 255)
    _polyline(layers[CHANNEL_INDEX["lane_centre"]], to_px(lane.centre))
    for boundary, line in ((lane.left, lane.left_line), (lane.right, lane.right_line)):
        if line in (LineType.SOLID, LineType.SOLID_THICK):
            _polyline(layers[CHANNEL_INDEX["lane_solid"]], to_px(boundary))
        elif line == LineType.DASHED:
            for dash in _dashes(boundary, lane.start_s):
                _polyline(layers[CHANNEL_INDEX["lane_dashed"]], to_px(dash))


def _box_px(scene: Scene, agent: int, step: int, origin: np.ndarray, heading: float,
            config: RasterConfig) -> np.ndarray:
    state = scene.states[agent, step]
    length, width = scene.sizes[agent]
    corners = box_corners(state[:2], state[2:4], length, width)
    return _shrink_box(pixel_from_ego(ego_from_world(corners, origin, heading), config))


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
            _fill(layers[CHANNEL_INDEX[channel]], _box_px(scene, agent, step, origin, heading, config),
                  value)
    return layers
