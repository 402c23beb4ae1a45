"""The ego's route ahead on the lanelets, held before a red light (`route_on_lanelets`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from rasterize.commonroad.lanes import _arc_length, _distance_to_polyline
from rasterize.commonroad.lights import LaneletLight, governing, movement_red, turn_between
from rasterize.geometry import Polyline, drop_repeats
from rasterize.highway import RouteRule
from rasterize.scene import STATE_DIM


def _heading_cos(lanelet, state: np.ndarray) -> float:
    """Cosine between the vehicle's heading and the lanelet's direction at the nearest segment."""
    centre = np.asarray(lanelet.center_vertices)
    seg = np.argmin(np.linalg.norm(centre[:-1] - state[:2], axis=1))
    d = centre[seg + 1] - centre[seg]
    return float(np.dot(d, state[2:4]) / max(np.linalg.norm(d), 1e-9))


ALIGNED_COS = float(np.cos(np.pi / 4))   # a lanelet within 45 degrees of the heading is driven along
NEAR_LANELET_M = 3.5                     # recorded positions may lie beside the mapped lanelets


def _lanelet_under(network, state: np.ndarray, rank: Callable[[int], float] | None = None):
    """The lanelet the vehicle is on, preferring the one whose direction matches its heading.

    With `rank` (lanelet id -> score: a recorded vehicle's use of each lanelet) only lanelets
    within 45 degrees of the heading count: among those under the vehicle the highest score,
    then the best heading; with none under it, the same among those whose centre line is within
    `NEAR_LANELET_M` (NGSIM tracks inside intersections leave the mapped turning lanelets); with
    none there either, None (off the lanelets). Without `rank`: the best heading under it."""
    ids = network.find_lanelet_by_position([np.asarray(state[:2])])[0]
    if rank is not None:
        under = [network.find_lanelet_by_id(i) for i in ids]
        aligned = [ll for ll in under if _heading_cos(ll, state) > ALIGNED_COS]
        if not aligned:
            aligned = [ll for ll in network.lanelets
                       if _distance_to_polyline(np.asarray(state[:2]), np.asarray(ll.center_vertices))
                       <= NEAR_LANELET_M and _heading_cos(ll, state) > ALIGNED_COS]
        return max(aligned, key=lambda ll: (rank(int(ll.lanelet_id)), _heading_cos(ll, state)),
                   default=None)
    best, best_cos = None, -np.inf
    for lanelet_id in ids:
        lanelet = network.find_lanelet_by_id(lanelet_id)
        cos = _heading_cos(lanelet, state)
        if cos > best_cos:
            best, best_cos = lanelet, cos
    return best


def _centre_line_ahead(network, state: np.ndarray, length_m: float,
                       successor: Callable[[Sequence[int]], int] | None = None,
                       rank: Callable[[int], float] | None = None
                       ) -> tuple[np.ndarray, list[int]] | None:
    """The centre line [K, 2] from the vehicle's projection on its lanelet through the lanelet's
    successors for at least `length_m`, and the ids of the lanelets it runs along, or None off the
    lanelets. `successor` picks one of several successors (default: the lowest id), `rank` the
    lanelet it is on among overlapping ones (`_lanelet_under`); a lanelet without successors ends
    the line."""
    lanelet = _lanelet_under(network, state, rank)
    if lanelet is None:
        return None
    centre = Polyline(np.asarray(lanelet.center_vertices, dtype=np.float64))
    seg, t, _ = centre.nearest(state[:2])
    proj = centre.points[seg] + t * centre.segments[seg]
    points = [proj[None], centre.points[seg + 1:]]
    total = _arc_length(np.concatenate(points))
    ids = [int(lanelet.lanelet_id)]
    while total < length_m and lanelet.successor:
        successors = [int(s) for s in lanelet.successor]
        nxt = min(successors) if successor is None or len(successors) == 1 else int(successor(successors))
        if nxt in ids:
            break
        ids.append(nxt)
        lanelet = network.find_lanelet_by_id(nxt)
        more = np.asarray(lanelet.center_vertices, dtype=np.float64)
        points.append(more)
        total += _arc_length(more)
    return drop_repeats(np.concatenate(points)), ids


def _first_crossing(line: np.ndarray, s_line: np.ndarray, segment: np.ndarray,
                    margin_m: float = 0.5) -> float | None:
    """Arc length along polyline `line` (cumulative lengths `s_line`) where it first crosses
    `segment` [2, 2] (extended by `margin_m` at both ends), or None."""
    p, r = segment[0], segment[1] - segment[0]
    length = float(np.linalg.norm(r))
    if length < 1e-9:
        return None
    u_pad = margin_m / length
    a, d = line[:-1], np.diff(line, axis=0)
    denom = d[:, 0] * r[1] - d[:, 1] * r[0]
    ok = np.abs(denom) > 1e-12
    q = p - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (q[:, 0] * r[1] - q[:, 1] * r[0]) / denom          # along the route segment
        u = (q[:, 0] * d[:, 1] - q[:, 1] * d[:, 0]) / denom    # along the stop line
    hits = np.flatnonzero(ok & (t >= 0) & (t <= 1) & (u >= -u_pad) & (u <= 1 + u_pad))
    if hits.size == 0:
        return None
    k = int(hits[0])
    return float(s_line[k] + t[k] * (s_line[k + 1] - s_line[k]))


def time_to_cover(distance_m: float, speed_mps: float, accel_mps2: float, limit_mps: float) -> float:
    """Seconds to drive `distance_m` from `speed_mps`, gaining `accel_mps2` up to `limit_mps`
    (inf when standing without acceleration)."""
    if distance_m <= 0:
        return 0.0
    v0 = max(speed_mps, 0.0)
    top = max(limit_mps, v0)
    if accel_mps2 <= 0 or v0 >= top:
        return distance_m / v0 if v0 > 0 else float("inf")
    t_top = (top - v0) / accel_mps2
    d_top = v0 * t_top + 0.5 * accel_mps2 * t_top ** 2
    if distance_m <= d_top:
        return float((-v0 + np.sqrt(v0 * v0 + 2.0 * accel_mps2 * distance_m)) / accel_mps2)
    return t_top + (distance_m - d_top) / top


FRONT_MARGIN_M = 0.5     # a held goal keeps the ego's front at least this far before the line
CREEP_MPS = 1.0          # at most this fast, a vehicle past a stop line is waiting, not committed
COMMIT_DECEL_MPS2 = 3.0  # a moving vehicle that needs more than this to stop at the line goes


def red_light_hold(network, line: np.ndarray, s_line: np.ndarray, ids: Sequence[int],
                   lights: Mapping[int, Sequence[LaneletLight]], ego_state: np.ndarray,
                   ego_length_m: float, now_s: float, rule: RouteRule, speed_limit_mps: float,
                   stop_gap_m: float, reach_m: float) -> float | None:
    """Route distance (m from the ego's centre, >= 0) at which the goal is held before a red
    light, or None.

    The signals of the route's lanelets (`ids`, and the lanelet before the first, whose stop line
    the ego may be straddling) are visited in route order while their hold point is within
    `reach_m`. The first stop line that the ego's rear has not passed, whose lights (for the
    route's turn there) are red when the ego's front would reach it, holds the goal point
    `stop_gap_m` before the line, and at least `FRONT_MARGIN_M` farther back than half the ego's
    length, so that an ego at its goal has not put its front across the line (an ego already
    closer than that is held where it is). A moving ego (faster than `CREEP_MPS`) that cannot stop
    its front at the line braking `COMMIT_DECEL_MPS2` is committed: that signal does not hold.
    Recorded drivers wait with their front past the mapped stop line (NGSIM: by about 2 m), so a
    front past the line alone does not commit a slow one."""
    speed = max(float(ego_state[4]), 0.0)
    half = 0.5 * ego_length_m
    # Look behind the ego's centre as far as its rear (and a metre more).
    back = half + 1.0
    line = np.concatenate([ego_state[None, :2] - back * ego_state[2:4], line])
    s_line = np.concatenate([[-back], s_line])
    first = network.find_lanelet_by_id(ids[0]) if ids else None
    visits = [(int(p), ids[0]) for p in (getattr(first, "predecessor", None) or ()) if int(p) in lights]
    visits += [(lanelet_id, ids[k + 1] if k + 1 < len(ids) else None) for k, lanelet_id in enumerate(ids)]
    for lanelet_id, nxt in visits:
        if lanelet_id not in lights:
            continue
        turn = turn_between(network, lanelet_id, nxt) if nxt is not None else None
        governed = governing(lights[lanelet_id], turn)
        if not governed:
            continue
        s_stop = _first_crossing(line, s_line, governed[0].stop_line)
        if s_stop is None:
            continue
        if s_stop <= -half:
            continue                                    # the rear is past: behind the ego
        front_to_line = s_stop - half
        if speed > CREEP_MPS and front_to_line < speed * speed / (2.0 * COMMIT_DECEL_MPS2):
            continue                                    # cannot stop comfortably: committed
        hold = s_stop - max(stop_gap_m, half + FRONT_MARGIN_M)
        if hold > reach_m:
            break
        arrival = now_s + time_to_cover(max(front_to_line, 0.0), speed, rule.accel_mps2,
                                        speed_limit_mps)
        if np.isfinite(arrival) and movement_red(governed, arrival):
            return max(0.0, hold)
    return None


def route_on_lanelets(network, ego_state: np.ndarray, ego_length_m: float, others: np.ndarray,
                      other_lengths_m: np.ndarray, rule: RouteRule | None = None,
                      speed_limit_mps: float = 29.06, *,
                      successor: Callable[[Sequence[int]], int] | None = None,
                      rank: Callable[[int], float] | None = None,
                      lights: Mapping[int, Sequence[LaneletLight]] | None = None,
                      now_s: float = 0.0, stop_gap_m: float = 2.0) -> np.ndarray:
    """[rule.points, 2] world points from the ego along its lane to its goal (the route rule).

    Free distance = min(limit × T, v × T + a T² / 2); a leader within the rule's half-width of the
    route caps it at the leader's position after T less a standstill gap and a time headway; a red
    light ahead (`lights` by lanelet id, states at `now_s` s from the recording's step 0) holds it
    before its stop line (`red_light_hold`). `successor` picks the way through intersections
    (default: the lowest successor id) and `rank` the lanelet the ego is on where lanelets
    overlap (default: the best heading). Off the lanelets the route runs straight ahead along the
    ego's heading.
    """
    rule = rule or RouteRule()
    t = rule.horizon_s
    speed = max(float(ego_state[4]), 0.0)
    free = min(speed_limit_mps * t, speed * t + 0.5 * rule.accel_mps2 * t * t)
    reach = free + 40.0                                   # look for leaders a little further
    ahead = _centre_line_ahead(network, ego_state, reach, successor, rank)
    line, ids = ahead if ahead is not None else (None, [])
    if line is None or len(line) < 2:
        line, ids = np.stack([ego_state[:2], ego_state[:2] + reach * ego_state[2:4]]), []
    line = np.concatenate([ego_state[None, :2], line[1:]]) if len(line) > 1 else line
    route = Polyline(line)
    s_line = route.arc
    along = np.arange(0.0, reach + rule.sample_m, rule.sample_m)
    dense = route.point_at(along)
    distance = free
    for other, length in zip(np.asarray(others).reshape(-1, STATE_DIM), np.asarray(other_lengths_m)):
        if np.linalg.norm(other[:2] - ego_state[:2]) > reach + 10.0:
            continue
        offsets = np.linalg.norm(dense - other[:2], axis=1)
        j = int(np.argmin(offsets))
        if j == 0 or offsets[j] > rule.lane_half_width_m:
            continue                                      # beside or behind, or off the route
        direction = dense[min(j + 1, len(dense) - 1)] - dense[max(j - 1, 0)]
        direction /= max(np.linalg.norm(direction), 1e-9)
        v_lead = max(0.0, float(np.dot(other[4] * other[2:4], direction)))
        gap = along[j] - 0.5 * (ego_length_m + float(length))
        cap = gap + v_lead * t - (rule.standstill_gap_m + v_lead * rule.headway_s)
        distance = min(distance, max(0.0, cap))
    if lights and ids:
        held = red_light_hold(network, line, s_line, ids, lights, ego_state, ego_length_m, now_s,
                              rule, speed_limit_mps, stop_gap_m, reach_m=free)
        if held is not None:
            distance = min(distance, held)
    ds = np.linspace(0.0, distance, rule.points)
    return np.stack([np.interp(ds, along, dense[:, 0]), np.interp(ds, along, dense[:, 1])], axis=1)
