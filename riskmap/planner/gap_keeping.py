"""Gap keeping: the timing of a planned path never runs into a vehicle ahead on it.

The risk map and the sampler decide *where* the ego goes (a path of cells); the waypoint timing
(`riskmap.planner.sampler`) decides *when*, from the ego's speed and the path's length alone. In
stop-and-go traffic that timing can put the ego where the car ahead will be: the path is free
of risk in space but not in time. Here each other vehicle is predicted at constant velocity;
where its predicted centre lies on the path (within half the two widths plus a margin of the
path's centre line) at a waypoint's time, the ego's distance along the path at that time is
capped at the vehicle's, less half the two lengths, a standstill gap and a time headway at the
vehicle's speed along the path. Distances are then made to respect every later cap too
(s_k ≤ min over j ≥ k of cap_j), so the plan never has to back off, stay non-decreasing and,
once held back, advance no faster than the plan did.

This is our addition to the planner paper's sampler (it has no notion of time along the path);
`SamplerConfig.keep_gap` switches it, and checkpoints from before it existed plan without (their
sidecars are upgraded so: `riskmap.infra.checkpoint`).

Shapes: waypoints [K, 2] ego frame (x forward, y left), metres, at `dt_s` steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.frames import ego_from_world, ego_pose
from rasterize.predict import predict_along_lanes
from rasterize.scene import Scene


@dataclass(frozen=True)
class GapKeepingConfig:
    """Defaults from recorded US-101 drivers: applied to the humans' own 6 s futures (every other
    training window), 1 m and no headway leave 90% of them within 0.5 m (mean shift 0.77 m);
    a 1 s headway would move 38% of them (mean 3.3 m) — under a constant-velocity prediction of
    the car ahead, NGSIM drivers follow closer than that (experiments/README.md)."""

    standstill_m: float = 1.0         # bumper to bumper, at the predicted position ahead
    headway_s: float = 0.0            # plus this many seconds at the vehicle's speed
    lateral_margin_m: float = 0.3     # on the path: centre within half the widths plus this


def _project(points: np.ndarray, line: np.ndarray, arc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(arc length of the nearest point on `line`, distance to it) for each of `points` [N, 2];
    `line` [M, 2] with cumulative arc lengths `arc` [M]."""
    a, b = line[:-1], line[1:]
    ab = b - a
    seg_len2 = np.maximum((ab * ab).sum(axis=1), 1e-12)
    t = np.clip(((points[:, None, :] - a[None]) * ab[None]).sum(axis=2) / seg_len2[None], 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]                        # [N, M-1, 2]
    dist = np.linalg.norm(points[:, None, :] - nearest, axis=2)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(points))
    along = arc[best] + t[rows, best] * np.sqrt(seg_len2[best])
    return along, dist[rows, best]


PREDICTIONS = ("straight", "lanes")


def keep_gap(waypoints: np.ndarray, scene: Scene, dt_s: float,
             config: GapKeepingConfig = GapKeepingConfig(), prediction: str = "straight"
             ) -> np.ndarray:
    """`waypoints` re-timed along their own path so the ego stays behind every vehicle predicted
    on it (module doc); unchanged where nobody is in the way. `prediction`: the others at
    constant velocity along their heading (`straight`, as checkpoints were tuned with) or at
    constant speed along their lanes (`lanes`, `rasterize.predict`: a car turning across the
    ego's path is seen where it will be, not where its heading points)."""
    line = np.concatenate([np.zeros((1, 2)), waypoints])
    steps = np.linalg.norm(np.diff(line, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(steps)])
    if arc[-1] <= 1e-6:
        return waypoints
    keep = np.concatenate([[True], steps > 1e-9])           # drop repeated points for projection
    line_u, arc_u = line[keep], arc[keep]
    if len(line_u) < 2:
        return waypoints
    origin, heading = ego_pose(scene)
    now = scene.current_index
    ego_len, ego_wid = scene.sizes[scene.ego_index]
    times = dt_s * np.arange(1, len(waypoints) + 1)
    cap = np.full(len(waypoints), np.inf)
    if prediction == "lanes":
        lane_xy, lane_heading = predict_along_lanes(scene, float(times[-1]), dt_s)   # [N, K, 2]
    for agent in range(scene.num_agents):
        if agent == scene.ego_index or not scene.valid[agent, now]:
            continue
        state = scene.states[agent, now]
        position = ego_from_world(state[:2][None], origin, heading)[0]
        if position[0] <= 0.0:        # only vehicles ahead now: one behind that overtakes is no leader
            continue
        if prediction == "lanes":
            predicted = ego_from_world(lane_xy[agent], origin, heading)                 # [K, 2]
            ahead_xy = ego_from_world(lane_xy[agent] + state[4] * lane_heading[agent], origin, heading)
            velocity = ahead_xy - predicted                                            # [K, 2]
        else:
            velocity = ego_from_world((state[:2] + state[4] * state[2:4])[None], origin,
                                      heading)[0] - position
            predicted = position[None] + times[:, None] * velocity[None]
            velocity = np.broadcast_to(velocity, predicted.shape)
        along, off = _project(predicted, line_u, arc_u)
        length, width = scene.sizes[agent]
        on_path = (off <= 0.5 * (ego_wid + width) + config.lateral_margin_m) & (along > 0.0)
        if not on_path.any():
            continue
        direction = np.diff(line_u, axis=0)
        seg = np.clip(np.searchsorted(arc_u, along, side="right") - 1, 0, len(direction) - 1)
        unit = direction[seg] / np.maximum(np.linalg.norm(direction[seg], axis=1, keepdims=True), 1e-9)
        speed_along = np.maximum((unit * velocity).sum(axis=1), 0.0)
        limit = along - 0.5 * (ego_len + length) - config.standstill_m - config.headway_s * speed_along
        cap = np.where(on_path, np.minimum(cap, limit), cap)
    if not np.isfinite(cap).any():
        return waypoints
    suffix_min = np.minimum.accumulate(cap[::-1])[::-1]
    # Held back, the ego goes on no faster than planned (it cannot catch up by jumping ahead).
    s = np.zeros(len(waypoints))
    previous = 0.0
    for k in range(len(waypoints)):
        previous = max(previous, min(previous + steps[k], suffix_min[k]))
        s[k] = previous
    if np.allclose(s, arc[1:]):
        return waypoints
    return np.column_stack([np.interp(s, arc_u, line_u[:, 0]), np.interp(s, arc_u, line_u[:, 1])])
