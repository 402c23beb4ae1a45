"""Where the other agents are about to be: constant speed along their lanes, from the present only.

`predict_along_lanes(scene, horizon_s, step_s)` returns, for every agent present now,
    xy       [N, K, 2]  world metres at the K times `prediction_times(horizon_s, step_s)` ahead
    heading  [N, K, 2]  unit heading vectors there (the lane's tangent while on a lane)
and NaN for agents absent now. Only the current state (`scene.states[:, scene.current_index]`)
is read: training scenes carry the recorded future, which is the label and must not leak into
the input.

The model: each agent is matched to the nearest lane centre line of `scene.lanes` that runs its
way (within `MAX_ANGLE_DEG` of its heading, within `MAX_OFFSET_M` of it) and advances along it at
its current speed, from the nearest point of the centre line (so its predicted boxes sit on the
lane's centre). At the end of a lane it goes on along the lane that starts there
(`JOIN_GAP_M`) in the same direction, choosing the turn that its yaw rate would make (straight
ahead at zero yaw rate); with no such lane it carries on straight. An agent no lane matches keeps
its velocity along its heading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.scene import Lane, Scene

MAX_ANGLE_DEG = 45.0     # an agent follows a lane only if it heads within this of the lane
MAX_OFFSET_M = 3.0       # ... and is at most this far from its centre line
JOIN_GAP_M = 1.5         # a lane continues another if it starts within this of the other's end
# Matching cost per unit of (1 - cos angle) to the lane, metres: where lanes overlap (the turns
# leaving one stop line) the one whose direction agrees with the agent's wins.
ANGLE_COST_M = 2.0
MAX_HOPS = 16            # lanes followed after the first (a guard against degenerate loops)
_COS_MAX = float(np.cos(np.deg2rad(MAX_ANGLE_DEG)))


def prediction_times(horizon_s: float, step_s: float = 0.5) -> np.ndarray:
    """Seconds ahead [K]: step_s, 2 step_s, ..., the last one exactly horizon_s (empty for 0)."""
    k = int(np.ceil(horizon_s / step_s - 1e-9)) if horizon_s > 0 else 0
    return np.minimum(step_s * np.arange(1, k + 1), horizon_s)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _wrap(angle):
    return (angle + np.pi) % (2 * np.pi) - np.pi


@dataclass(frozen=True)
class _LaneTable:
    """The scene's lane centre lines as flat arrays: P points over L lanes, S segments.

    Lane l's points are points[first[l]:last[l] + 1] (consecutive duplicates dropped). `gs` is
    an arc length along all lanes laid end to end with a 1 m gap between lanes, so that one
    `np.interp` serves every lane: lane l at arc length s (m) is gs[first[l]] + s.
    """

    points: np.ndarray            # [P, 2]
    gs: np.ndarray                # [P] increasing
    direction: np.ndarray         # [P, 2] unit direction of the segment from each point (a
                                  # lane's last point: that of its last segment)
    first: np.ndarray             # [L]
    last: np.ndarray              # [L]
    length: np.ndarray            # [L] m
    turn: np.ndarray              # [L] heading change from a lane's start to its end, rad
    joins: np.ndarray             # [L, L] bool: lane j continues lane i
    seg_start: np.ndarray         # [S] index of each segment's first point
    seg_len: np.ndarray           # [S] m


def _lane_table(lanes: tuple[Lane, ...]) -> _LaneTable:
    counts = np.array([len(lane.centre) for lane in lanes])
    points = np.concatenate([lane.centre for lane in lanes])
    lane_of = np.repeat(np.arange(len(lanes)), counts)
    same = lane_of[1:] == lane_of[:-1]
    keep = np.concatenate([[True], ~same | (np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-6)])
    points, lane_of = points[keep], lane_of[keep]
    delta = np.diff(points, axis=0)
    same = lane_of[1:] == lane_of[:-1]
    seg_len = np.where(same, np.linalg.norm(delta, axis=1), 0.0)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    first = np.searchsorted(lane_of, np.arange(len(lanes)))
    last = np.searchsorted(lane_of, np.arange(len(lanes)), side="right") - 1
    seg_start = np.flatnonzero(same)
    direction = np.zeros_like(points)
    direction[seg_start] = delta[seg_start] / seg_len[seg_start, None]
    has_segment = last > first
    direction[last[has_segment]] = direction[last[has_segment] - 1]
    start_dir, end_dir = direction[first], direction[last]
    turn = _wrap(np.arctan2(end_dir[:, 1], end_dir[:, 0]) - np.arctan2(start_dir[:, 1], start_dir[:, 0]))
    joins = ((np.linalg.norm(points[last][:, None] - points[first][None], axis=-1) <= JOIN_GAP_M)
             & (end_dir @ start_dir.T >= _COS_MAX) & has_segment[None])
    np.fill_diagonal(joins, False)
    return _LaneTable(points=points, gs=cum + lane_of, direction=direction, first=first, last=last,
                      length=cum[last] - cum[first], turn=turn,
                      joins=joins,
                      seg_start=seg_start, seg_len=seg_len[seg_start])


def _match(table: _LaneTable, xy: np.ndarray, heading: np.ndarray):
    """Each agent's lane segment (index into table.seg_*), or -1, and the fraction along it
    [0, 1] of its projection; agents [M]."""
    seg_a = table.points[table.seg_start]
    seg_d = table.direction[table.seg_start] * table.seg_len[:, None]
    rel = xy[:, None, :] - seg_a[None]                                             # [M, S, 2]
    frac = np.clip((rel * seg_d).sum(-1) / table.seg_len**2, 0.0, 1.0)
    offset = np.linalg.norm(rel - frac[..., None] * seg_d, axis=-1)
    cos = heading @ table.direction[table.seg_start].T
    cost = np.where((offset <= MAX_OFFSET_M) & (cos >= _COS_MAX),
                    offset + ANGLE_COST_M * (1.0 - cos), np.inf)
    best = np.argmin(cost, axis=1)
    rows = np.arange(len(xy))
    return np.where(np.isfinite(cost[rows, best]), best, -1), frac[rows, best]


def _next_lane(table: _LaneTable, lane: int, speed: float, yaw_rate: float) -> int | None:
    """The lane that continues `lane`: the one whose turn is nearest the one the agent's yaw
    rate would make over it (so straight ahead at zero yaw rate); None if none does."""
    options = np.flatnonzero(table.joins[lane])
    if len(options) == 0:
        return None
    expected = np.clip(yaw_rate * table.length[options] / max(speed, 0.1), -np.pi, np.pi)
    return int(options[np.argmin(np.abs(table.turn[options] - expected))])


def _on_lanes(table: _LaneTable, lane: int, along: np.ndarray, speed: float, yaw_rate: float):
    """Where arc lengths `along` [K] (m from `lane`'s start) fall on the lanes that follow it:
    (lane [K], arc length on that lane [K], metres past the end of the last lane [K])."""
    lanes, starts = [lane], [0.0]
    for _ in range(MAX_HOPS):
        end = starts[-1] + table.length[lanes[-1]]
        if end >= along[-1]:
            break
        nxt = _next_lane(table, lanes[-1], speed, yaw_rate)
        if nxt is None:
            break
        lanes.append(nxt)
        starts.append(end)
    which = np.searchsorted(starts, along, side="right") - 1
    chain = np.asarray(lanes)[which]
    local = along - np.asarray(starts)[which]
    beyond = np.maximum(local - table.length[chain], 0.0)
    return chain, local - beyond, beyond


def predict_along_lanes(scene: Scene, horizon_s: float, step_s: float = 0.5
                        ) -> tuple[np.ndarray, np.ndarray]:
    """(xy [N, K, 2], heading [N, K, 2]) at `prediction_times(horizon_s, step_s)` (see the module
    docstring); NaN for agents absent now."""
    times = prediction_times(horizon_s, step_s)
    n = scene.num_agents
    xy = np.full((n, len(times), 2), np.nan)
    heading = np.full((n, len(times), 2), np.nan)
    present = np.flatnonzero(scene.valid[:, scene.current_index])
    now = scene.states[present, scene.current_index]
    pos, fwd = now[:, 0:2], _unit(now[:, 2:4])
    speed, yaw_rate = np.maximum(now[:, 4], 0.0), now[:, 5]   # nobody reverses in these data
    dist = speed[:, None] * times[None]                                            # [M, K]
    # Default: constant velocity along the heading; lane followers are overwritten below.
    xy[present] = pos[:, None] + dist[..., None] * fwd[:, None]
    heading[present] = fwd[:, None]
    if not scene.lanes or not len(times):
        return xy, heading
    table = _lane_table(scene.lanes)
    if not len(table.seg_start):
        return xy, heading
    segs, fracs = _match(table, pos, fwd)
    followers = np.flatnonzero(segs >= 0)
    if not len(followers):
        return xy, heading
    # Arc length of each follower's projection from its lane's start, then of its future.
    start = table.seg_start[segs[followers]]
    lane = np.searchsorted(table.first, start, side="right") - 1
    s0 = table.gs[start] - table.gs[table.first[lane]] + fracs[followers] * table.seg_len[segs[followers]]
    placed = [_on_lanes(table, int(l), s0[i] + dist[m], speed[m], yaw_rate[m])
              for i, (m, l) in enumerate(zip(followers, lane))]
    chain, local, beyond = (np.stack(parts) for parts in zip(*placed))             # [F, K]
    # All followers at once: one interpolation over every lane laid end to end.
    g = table.gs[table.first[chain]] + local
    point = np.clip(np.searchsorted(table.gs, g, side="right") - 1, table.first[chain],
                    table.last[chain])
    tangent = table.direction[point]
    out = np.stack([np.interp(g, table.gs, table.points[:, 0]),
                    np.interp(g, table.gs, table.points[:, 1])], axis=-1)
    xy[present[followers]] = out + beyond[..., None] * tangent
    heading[present[followers]] = tangent
    return xy, heading
