"""A window `Scene` as the traffic model's input: agents, vectorised lanes and a drivable field.

Everything is in the *scene frame*: the ego's pose at the current step is the origin and its
heading is +x. Shapes, stated once (N agents after selection, H = 5 past steps including the
current one, F = 12 future steps, L lane chunks per agent, P points per chunk, Q lane points):

    past         [N, H, 5]   (x, y, cos, sin, speed) at t0 - 2 s ... t0, scene frame, m and m/s
    past_valid   [N, H]
    future       [N, F, 5]   the same at t0 + 0.5 s ... t0 + 6 s (zeros where unknown)
    future_valid [N, F]
    sizes        [N, 2]      (length, width), m
    chunks       [N, L, P, 4] lane centre points near each agent, (x, y, dir_x, dir_y) in that
                              agent's own frame at t0; chunk_valid [N, L]
    lane_points  [Q, 4]      every lane centre point (x, y, dir_x, dir_y), scene frame
    off_road     OffRoadField: distance (m) to the drivable area on a grid over the scene frame

Row 0 is the ego; the others are the agents present at t0 within `radius_m`, nearest first
(the order `TrafficRecorder.scene` uses), at most `max_agents` in all. `rows` maps each row
back to its row in the window `Scene`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.path import Path as PolygonPath
from scipy.ndimage import distance_transform_edt

from rasterize.errors import InputError
from rasterize.frames import ego_from_world, heading_angle
from rasterize.scene import Scene
from rasterize.timebase import HISTORY_S, PLAN_DT_S, PLAN_STEPS

PAST_STEPS = round(HISTORY_S / PLAN_DT_S) + 1   # 5: 2 s of history at 2 Hz, the current step included
FUTURE_STEPS = PLAN_STEPS                       # 12: 6 s at 2 Hz
STEP_S = PLAN_DT_S                              # 0.5 s


@dataclass(frozen=True)
class FeatureConfig:
    max_agents: int = 12           # the ego included
    radius_m: float = 60.0         # others farther than this from the ego at t0 are left out
    lane_chunks: int = 8           # lane chunks per agent (map tokens of the map encoder)
    chunk_points: int = 8          # points per chunk
    point_spacing_m: float = 2.5   # spacing of lane points along a lane
    field_cell_m: float = 0.5      # cell size of the off-road distance field
    field_margin_m: float = 40.0   # the field covers every agent's positions plus this margin


@dataclass(frozen=True, eq=False)
class OffRoadField:
    """Distance (m) from a cell centre to the nearest drivable cell (0 on the road).

    distance [rows, cols]; cell (r, c) has its centre at (x0 + (c + 0.5) cell, y0 + (r + 0.5) cell)
    in the scene frame. Outside the grid the distance is that of the nearest border cell.
    """

    distance: np.ndarray
    x0: float
    y0: float
    cell_m: float

    def sample(self, xy: np.ndarray) -> np.ndarray:
        """Nearest-cell distances at points [..., 2] (numpy; the model samples it bilinearly)."""
        col = np.clip(((xy[..., 0] - self.x0) / self.cell_m).astype(int), 0, self.distance.shape[1] - 1)
        row = np.clip(((xy[..., 1] - self.y0) / self.cell_m).astype(int), 0, self.distance.shape[0] - 1)
        return self.distance[row, col]


@dataclass(frozen=True, eq=False)
class SceneTensors:
    past: np.ndarray
    past_valid: np.ndarray
    future: np.ndarray
    future_valid: np.ndarray
    sizes: np.ndarray
    chunks: np.ndarray
    chunk_valid: np.ndarray
    lane_points: np.ndarray
    off_road: OffRoadField
    rows: np.ndarray               # [N] row of each agent in the window Scene
    origin: np.ndarray             # [2] world position of the scene frame's origin
    heading: float                 # world heading (rad) of the scene frame's +x axis

    @property
    def num_agents(self) -> int:
        return self.past.shape[0]

    def world_xy(self, xy: np.ndarray) -> np.ndarray:
        """Scene-frame points [..., 2] in the world frame."""
        c, s = np.cos(self.heading), np.sin(self.heading)
        return self.origin + np.stack([c * xy[..., 0] - s * xy[..., 1],
                                       s * xy[..., 0] + c * xy[..., 1]], axis=-1)

    def world_states(self, states: np.ndarray) -> np.ndarray:
        """Scene-frame states [..., 5] (x, y, cos, sin, speed) as world states [..., 6]
        (x, y, heading_x, heading_y, speed, yaw_rate); the yaw rate is left at zero."""
        out = np.zeros(states.shape[:-1] + (6,))
        out[..., :2] = self.world_xy(states[..., :2])
        c, s = np.cos(self.heading), np.sin(self.heading)
        out[..., 2] = c * states[..., 2] - s * states[..., 3]
        out[..., 3] = s * states[..., 2] + c * states[..., 3]
        out[..., 4] = states[..., 4]
        return out


def select_rows(scene: Scene, config: FeatureConfig) -> np.ndarray:
    """The ego's row, then the rows present now within `radius_m`, nearest first."""
    now = scene.current_index
    ego = scene.ego_index
    if not scene.valid[ego, now]:
        raise InputError("scene: the ego is not present at the current step")
    dist = np.linalg.norm(scene.states[:, now, :2] - scene.states[ego, now, :2], axis=1)
    others = [i for i in np.argsort(dist, kind="stable")
              if i != ego and scene.valid[i, now] and dist[i] <= config.radius_m]
    return np.array([ego] + others[: config.max_agents - 1], dtype=np.int64)


def _to_frame(states: np.ndarray, origin: np.ndarray, heading: float) -> np.ndarray:
    """World states [..., 6] as (x, y, cos, sin, speed) [..., 5] in the frame (origin, heading)."""
    out = np.zeros(states.shape[:-1] + (5,))
    out[..., :2] = ego_from_world(states[..., :2].reshape(-1, 2), origin, heading).reshape(
        states.shape[:-1] + (2,))
    c, s = np.cos(heading), np.sin(heading)
    out[..., 2] = c * states[..., 2] + s * states[..., 3]
    out[..., 3] = -s * states[..., 2] + c * states[..., 3]
    out[..., 4] = states[..., 4]
    return out


def _resample(polyline: np.ndarray, spacing_m: float) -> np.ndarray:
    """Points (x, y, dir_x, dir_y) [K, 4] every `spacing_m` along a polyline [P, 2]."""
    seg = np.diff(polyline, axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 1e-6
    if not keep.any():
        return np.zeros((0, 4))
    polyline = np.concatenate([polyline[:1], polyline[1:][keep]])
    seg, length = seg[keep], length[keep]
    cum = np.concatenate([[0.0], np.cumsum(length)])
    s = np.arange(0.0, cum[-1] + 1e-9, spacing_m)
    idx = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    direction = seg[idx] / length[idx, None]
    xy = polyline[idx] + (s - cum[idx])[:, None] * direction
    return np.concatenate([xy, direction], axis=1)


def _lane_chunks(lanes_scene: list[np.ndarray], config: FeatureConfig) -> np.ndarray:
    """Consecutive chunks [C, P, 4] of every lane's resampled centre points (scene frame)."""
    p = config.chunk_points
    chunks = []
    for points in lanes_scene:
        for start in range(0, max(len(points) - 1, 1), p - 1):    # chunks share end points
            piece = points[start:start + p]
            if len(piece) < 2:
                continue
            if len(piece) < p:      # pad a short tail by repeating its last point
                piece = np.concatenate([piece, np.repeat(piece[-1:], p - len(piece), axis=0)])
            chunks.append(piece)
    return np.array(chunks).reshape(-1, p, 4)


def _rotate_points(points: np.ndarray, origin: np.ndarray, heading: float) -> np.ndarray:
    """(x, y, dir_x, dir_y) points [..., 4] into the frame (origin, heading)."""
    c, s = np.cos(heading), np.sin(heading)
    d = points[..., :2] - origin
    return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1],
                     c * points[..., 2] + s * points[..., 3], -s * points[..., 2] + c * points[..., 3]],
                    axis=-1)


def off_road_field(polygons: list[np.ndarray], lo: np.ndarray, hi: np.ndarray, cell_m: float
                   ) -> OffRoadField:
    """The distance field over the box [lo, hi] (scene frame) of the union of `polygons`."""
    cols = max(1, int(np.ceil((hi[0] - lo[0]) / cell_m)))
    rows = max(1, int(np.ceil((hi[1] - lo[1]) / cell_m)))
    xs = lo[0] + (np.arange(cols) + 0.5) * cell_m
    ys = lo[1] + (np.arange(rows) + 0.5) * cell_m
    drivable = np.zeros((rows, cols), bool)
    for polygon in polygons:
        # Only the cells under the polygon's bounding box are tested.
        c0, r0 = np.floor((polygon.min(axis=0) - lo) / cell_m).astype(int)
        c1, r1 = np.ceil((polygon.max(axis=0) - lo) / cell_m).astype(int) + 1
        c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, cols), min(r1, rows)
        if c0 >= c1 or r0 >= r1:
            continue
        sub = np.stack(np.meshgrid(xs[c0:c1], ys[r0:r1]), axis=-1).reshape(-1, 2)
        drivable[r0:r1, c0:c1] |= PolygonPath(polygon).contains_points(sub).reshape(r1 - r0, c1 - c0)
    if not drivable.any():
        raise InputError("scene: no lane covers the area around the agents; the scene has no map")
    distance = distance_transform_edt(~drivable) * cell_m
    return OffRoadField(distance.astype(np.float32), float(lo[0]), float(lo[1]), cell_m)


def scene_tensors(scene: Scene, config: FeatureConfig = FeatureConfig()) -> SceneTensors:
    """The traffic model's view of a window scene (module docstring). The scene must have
    PAST_STEPS - 1 steps of history at STEP_S; the future may be absent (then it is invalid)."""
    now = scene.current_index
    if now < PAST_STEPS - 1 or abs(scene.dt - STEP_S) > 1e-6:
        raise InputError(f"scene: the traffic model needs {PAST_STEPS - 1} past steps at {STEP_S} s "
                         f"(got current_index {now}, dt {scene.dt:g} s); collect 2 s of history at 2 Hz")
    if not scene.lanes:
        raise InputError("scene: it has no lanes; the traffic model needs the map around the agents")
    rows = select_rows(scene, config)
    ego_now = scene.states[scene.ego_index, now]
    origin, heading = ego_now[:2].astype(np.float64), float(heading_angle(ego_now[2:4]))
    states = scene.states[rows].astype(np.float64)
    valid = scene.valid[rows]
    framed = _to_frame(states, origin, heading)
    past = framed[:, now - PAST_STEPS + 1: now + 1]
    past_valid = valid[:, now - PAST_STEPS + 1: now + 1]
    future = np.zeros((len(rows), FUTURE_STEPS, 5))
    future_valid = np.zeros((len(rows), FUTURE_STEPS), bool)
    known = min(FUTURE_STEPS, scene.num_steps - now - 1)
    future[:, :known] = framed[:, now + 1: now + 1 + known]
    future_valid[:, :known] = valid[:, now + 1: now + 1 + known]
    future[~future_valid] = 0.0
    past = np.where(past_valid[..., None], past, 0.0)

    lanes_scene = [_rotate_points(_resample(lane.centre, config.point_spacing_m), origin, heading)
                   for lane in scene.lanes]
    lanes_scene = [pts for pts in lanes_scene if len(pts)]
    lane_points = np.concatenate(lanes_scene)
    all_chunks = _lane_chunks(lanes_scene, config)
    chunks = np.zeros((len(rows), config.lane_chunks, config.chunk_points, 4))
    chunk_valid = np.zeros((len(rows), config.lane_chunks), bool)
    centres = all_chunks[:, :, :2].mean(axis=1)
    for i in range(len(rows)):
        pose = past[i, -1]
        order = np.argsort(np.linalg.norm(centres - pose[:2], axis=1), kind="stable")[: config.lane_chunks]
        chunks[i, : len(order)] = _rotate_points(all_chunks[order], pose[:2],
                                                 float(np.arctan2(pose[3], pose[2])))
        chunk_valid[i, : len(order)] = True

    polygons = [_rotate_points(np.concatenate([lane.polygon(), np.zeros_like(lane.polygon())], 1),
                               origin, heading)[:, :2] for lane in scene.lanes]
    # The field must cover where the agents can get to in 6 s, not only where they went.
    reach = past[:, -1, :2] + (FUTURE_STEPS * STEP_S) * past[:, -1, 4:5] * past[:, -1, 2:4]
    seen = np.concatenate([past[past_valid][:, :2], future[future_valid][:, :2], reach[past_valid[:, -1]],
                           np.zeros((1, 2))])
    lo = seen.min(axis=0) - config.field_margin_m
    hi = seen.max(axis=0) + config.field_margin_m
    field = off_road_field(polygons, lo, hi, config.field_cell_m)
    return SceneTensors(past.astype(np.float32), past_valid, future.astype(np.float32), future_valid,
                        scene.sizes[rows].astype(np.float32), chunks.astype(np.float32), chunk_valid,
                        lane_points.astype(np.float32), field, rows, origin, heading)
