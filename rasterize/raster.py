"""The ego-centred BEV raster, drawn with OpenCV.

`rasterize_scene(scene, config)` returns uint8 [C, rows, cols] with the channels of
`channels(config)` (255 = fully present). The ego faces up (row 0 is ahead), its left is column 0.

The first 8 channels (`CHANNELS`) are the paper's BEV raster: the map, and the present and the
last `history_s` seconds of the agents. With `config.predict_s` > 0 two channels of what is about
to happen follow (`FUTURE_CHANNELS`, our extension; the paper's raster shows only the present and
2 s of history):
    agents_future  the other agents' boxes over the next predict_s seconds at 0.5 s steps, at
                   constant speed along their lanes (`rasterize.predict`), fading with time ahead.
                   Predicted from the present state only, never from the recorded future.
    signal_red     each traffic light's stop line, as bright as the share of the next predict_s
                   seconds (sampled every 0.5 s from now) in which the light is red.
"""

from __future__ import annotations

import cv2
import numpy as np

from rasterize.config import RasterConfig
from rasterize.frames import ego_from_world, ego_pose, pixel_from_ego
from rasterize.geometry import Polyline
from rasterize.predict import predict_along_lanes, prediction_times
from rasterize.scene import Lane, LineType, Scene, Signal

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
# Appended after CHANNELS when RasterConfig.predict_s > 0.
FUTURE_CHANNELS: tuple[str, ...] = (
    "agents_future",   # other agents' predicted boxes over the next predict_s, fading with time
    "signal_red",      # stop lines, brightness = share of the next predict_s the light is red
)
CHANNEL_INDEX = {name: i for i, name in enumerate(CHANNELS)}   # the base channels'


def channels(config: RasterConfig) -> tuple[str, ...]:
    """The channel names of rasters drawn with `config`, in order."""
    return CHANNELS + FUTURE_CHANNELS if config.predict_s > 0 else CHANNELS


def channel_index(config: RasterConfig) -> dict[str, int]:
    """Channel name -> index in rasters drawn with `config`."""
    return {name: i for i, name in enumerate(channels(config))}


# Time step (s) of the predicted boxes and of the signal-state samples, and the brightness of
# the predicted box farthest ahead (the nearest is 255).
PREDICT_STEP_S = 0.5
FUTURE_DIMMEST = 64
# Thickness (m) of a drawn stop line.
STOP_LINE_M = 1.0

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


def _shrink_boxes(corners: np.ndarray) -> np.ndarray:
    """`_shrink_box` of many boxes at once: corners [..., 4, 2] in pixel space."""
    centre = corners.mean(axis=-2)
    a = 0.5 * (corners[..., 0, :] - corners[..., 3, :])
    b = 0.5 * (corners[..., 0, :] - corners[..., 1, :])
    area = np.abs(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])
    safe = np.maximum(area, 1e-12)
    a2 = a * np.maximum(0.0, 1.0 - 0.5 * np.linalg.norm(b, axis=-1) / safe)[..., None]
    b2 = b * np.maximum(0.0, 1.0 - 0.5 * np.linalg.norm(a, axis=-1) / safe)[..., None]
    shrunk = np.stack([centre + a2 + b2, centre + a2 - b2, centre - a2 - b2, centre - a2 + b2],
                      axis=-2)
    return np.where((area < 1e-12)[..., None, None], corners, shrunk)


def _shrink_strip(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pull the two sides of a lane strip [P, 2] towards each other by half a pixel each."""
    across = right - left
    norm = np.linalg.norm(across, axis=1, keepdims=True)
    step = np.minimum(0.5, 0.5 * norm) * across / np.maximum(norm, 1e-12)
    return left + step, right - step


def _fill(canvas: np.ndarray, polygon_colrow: np.ndarray, value: int) -> None:
    """Fill a polygon given in continuous (col, row) pixel coordinates (`_draw_agents_future`
    does the same for many boxes at once).

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
    boundary = Polyline(line, start_m=start_s)
    s = boundary.arc
    if boundary.length < 1e-9:
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
    pts = boundary.point_at(knots)
    ids = run_id[painted]
    pts = pts[painted]
    cuts = np.flatnonzero(np.diff(ids)) + 1
    return [run for run in np.split(pts, cuts) if len(run) >= 2]


def _inside(colrow: np.ndarray, config: RasterConfig, margin: float = 2.0) -> np.ndarray:
    return ((colrow[:, 0] > -margin) & (colrow[:, 0] < config.cols + margin)
            & (colrow[:, 1] > -margin) & (colrow[:, 1] < config.rows + margin))


def _visible(colrow: np.ndarray, config: RasterConfig) -> bool:
    return bool(_inside(colrow, config).any())


def _on_raster(boxes: np.ndarray, config: RasterConfig) -> np.ndarray:
    """Mask [...] of the boxes [..., 4, 2] (pixel space) whose bounding boxes reach the raster.

    By bounding box, not by corner: a box can cover pixels with every corner off the raster (a
    lorry across a corner of it). False for boxes with NaN corners.
    """
    lo, hi = boxes.min(axis=-2), boxes.max(axis=-2)
    return (hi[..., 0] > -1) & (lo[..., 0] < config.cols + 1) \
        & (hi[..., 1] > -1) & (lo[..., 1] < config.rows + 1)


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


def _box_corners(xy: np.ndarray, fwd: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Corners [..., 4, 2] of boxes at centres xy [..., 2] facing unit fwd [..., 2], sizes
    (length, width) [..., 2]; same order as `_boxes_px` (front-left, front-right, rear-right,
    rear-left)."""
    left = np.stack([-fwd[..., 1], fwd[..., 0]], axis=-1)
    half_l = 0.5 * sizes[..., 0:1] * fwd
    half_w = 0.5 * sizes[..., 1:2] * left
    signs_l = np.array([1, 1, -1, -1])[:, None]
    signs_w = np.array([1, -1, -1, 1])[:, None]
    return xy[..., None, :] + signs_l * half_l[..., None, :] + signs_w * half_w[..., None, :]


def future_intensity(ahead_s: np.ndarray, predict_s: float) -> np.ndarray:
    """Brightness of a box predicted `ahead_s` seconds ahead: 255 at the first step, fading
    linearly to FUTURE_DIMMEST at predict_s (sooner is surer)."""
    first = min(PREDICT_STEP_S, predict_s)
    span = max(predict_s - first, 1e-9)
    fade = np.clip((np.asarray(ahead_s, dtype=np.float64) - first) / span, 0.0, 1.0)
    return np.round(255 - (255 - FUTURE_DIMMEST) * fade).astype(int)


def red_intensity(signal: Signal, predict_s: float) -> int:
    """Brightness of a stop line: 255 x the share of the times 0, 0.5, ..., predict_s at which
    its light is red (red throughout 255, green throughout 0)."""
    times = np.concatenate([[0.0], prediction_times(predict_s, PREDICT_STEP_S)])
    return round(255 * float(np.mean([signal.red_at(t) for t in times])))


def _draw_agents_future(canvas: np.ndarray, scene: Scene, origin: np.ndarray, heading: float,
                        config: RasterConfig) -> None:
    """The other agents' predicted boxes, from the present state only (`predict_along_lanes`)."""
    xy, fwd = predict_along_lanes(scene, config.predict_s, PREDICT_STEP_S)      # [N, K, 2]
    others = scene.valid[:, scene.current_index].copy()
    others[scene.ego_index] = False
    if not others.any() or xy.shape[1] == 0:
        return
    xy, fwd, sizes = xy[others], fwd[others], scene.sizes[others]
    corners = _box_corners(xy, fwd, np.broadcast_to(sizes[:, None], xy.shape))   # [M, K, 4, 2]
    boxes = _shrink_boxes(pixel_from_ego(ego_from_world(corners, origin, heading), config))
    shown = _on_raster(boxes, config)
    values = future_intensity(prediction_times(config.predict_s, PREDICT_STEP_S),
                              config.predict_s)
    # All at once (this runs per training window); boxes not drawn become 0 so that far ones
    # do not overflow the int32 cast.
    vertices = _cv_points(np.where(shown[..., None, None], boxes, 0.0))
    # Latest first: the nearer, brighter boxes are painted over the dimmer ones, so each pixel
    # keeps the brightest (soonest) box that covers it.
    for k in range(xy.shape[1] - 1, -1, -1):
        for m in np.flatnonzero(shown[:, k]):
            cv2.fillPoly(canvas, [vertices[m, k]], int(values[k]), lineType=cv2.LINE_8,
                         shift=_SHIFT)


def _draw_signals(canvas: np.ndarray, scene: Scene, origin: np.ndarray, heading: float,
                  config: RasterConfig) -> None:
    """Stop lines STOP_LINE_M thick, as bright as the share of the horizon their light is red."""
    drawn = [(red_intensity(sig, config.predict_s), sig) for sig in scene.signals]
    # Dimmest first, so that where stop lines overlap the redder one shows.
    for value, sig in sorted((d for d in drawn if d[0] > 0), key=lambda d: d[0]):
        a, b = sig.stop_line
        along = b - a
        normal = 0.5 * STOP_LINE_M * np.array([-along[1], along[0]]) / max(np.linalg.norm(along),
                                                                          1e-12)
        corners = np.stack([b + normal, b - normal, a - normal, a + normal])
        px = pixel_from_ego(ego_from_world(corners, origin, heading), config)
        if _on_raster(px, config):
            _fill(canvas, _shrink_box(px), value)


def history_intensity(age_s: float, history_s: float, dt: float) -> int:
    """Brightness of a box drawn `age_s` seconds ago: fades linearly, the oldest still visible."""
    return round(255 * (1.0 - float(age_s) / (history_s + dt)))


def rasterize_scene(scene: Scene, config: RasterConfig) -> np.ndarray:
    """The BEV raster uint8 [len(channels(config)), rows, cols] of the scene at its current time."""
    layers = np.zeros((len(channels(config)), config.rows, config.cols), dtype=np.uint8)
    origin, heading = ego_pose(scene)
    for lane in scene.lanes:
        _draw_lane(layers, lane, origin, heading, config)

    now, ego = scene.current_index, scene.ego_index
    oldest = max(0, now - round(config.history_s / scene.dt))
    # Every box of the window shrunk and turned into OpenCV vertices at once; only the fills
    # run per box. Boxes wholly off the raster are skipped (OpenCV would clip them to nothing).
    boxes = _shrink_boxes(_boxes_px(scene, origin, heading, config)[:, oldest:now + 1])
    on_raster = scene.valid[:, oldest:now + 1] & _on_raster(boxes, config)   # [N, T]
    vertices = _cv_points(np.where(on_raster[..., None, None], boxes, 0.0))   # [N, T, 4, 2]
    for step in range(oldest, now + 1):  # oldest first: newer, brighter boxes overwrite
        age = (now - step) * scene.dt
        value = history_intensity(age, config.history_s, scene.dt)
        for agent in np.flatnonzero(on_raster[:, step - oldest]):
            is_ego = agent == ego
            if step == now:
                channel = "ego" if is_ego else "agents"
                value = 255
            else:
                channel = "ego_history" if is_ego else "agents_history"
            cv2.fillPoly(layers[CHANNEL_INDEX[channel]], [vertices[agent, step - oldest]],
                         int(value), lineType=cv2.LINE_8, shift=_SHIFT)
    if config.predict_s > 0:
        index = channel_index(config)
        _draw_agents_future(layers[index["agents_future"]], scene, origin, heading, config)
        _draw_signals(layers[index["signal_red"]], scene, origin, heading, config)
    return layers
