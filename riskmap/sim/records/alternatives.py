"""Ego-only alternatives to a recorded drive, and STRIVE's solution check built on them.

Both the solution check (here) and the avoidability of a failure (`riskmap.sim.records.failures`) ask
whether the ego alone, driving differently from some step on while everybody else does what
they did, would have hit nobody.

STRIVE's solution rate asks whether an ego-only re-optimisation finds a collision-free trajectory
against the adversarial scenario. Here the other agents replay what they did (the adversary
included), and the ego, from its recorded state `lookback_s` before the collision, tries a small
family of longitudinal alternatives along its own recorded path: constant accelerations
`accels_mps2` (speed clipped to [0, `max_speed_mps`]; past the end of the recorded path it goes
straight on). A solution exists if one alternative overlaps no other agent's box at any step up
to the collision step. By default lateral alternatives (another lane) are not searched, so this
is a lower bound on the solution rate; the path is the ego's own, so it stays on the road as the
ego did. With `lateral_offsets_m` the ego may also drift sideways off its path by each offset
(left positive, e.g. one lane width either way), blending in with a smoothstep over
`lateral_blend_s`, combined with every acceleration; `on_road(centre, heading, length, width)`
then rejects the alternatives that leave the road at any step.
"""

from __future__ import annotations

import numpy as np

from rasterize.frames import box_corners
from rasterize.geometry import boxes_overlap
from rasterize.tracks import Tracks
from riskmap.sim.records.metrics import min_box_gap

DEFAULT_ACCELS_MPS2 = (-8.0, -6.0, -4.0, -2.0, 0.0, 1.0, 2.0, 3.0)


def _along(path: np.ndarray, distance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(point [2], unit direction [2]) at arc length `distance_m` along the polyline path [P, 2]."""
    seg = np.diff(path, axis=0)
    lengths = np.linalg.norm(seg, axis=1)
    keep = lengths > 1e-6
    seg, lengths = seg[keep], lengths[keep]
    if len(seg) == 0:
        return path[0], np.array([1.0, 0.0])
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    i = int(np.clip(np.searchsorted(cum, distance_m, side="right") - 1, 0, len(seg) - 1))
    direction = seg[i] / lengths[i]
    return path[keep.nonzero()[0][i]] + (distance_m - cum[i]) * direction, direction


def ego_only_solution(tracks: Tracks, ego: int, collision_step: int, dt_s: float, lookback_s: float = 3.0,
                      accels_mps2: tuple[float, ...] = DEFAULT_ACCELS_MPS2,
                      max_speed_mps: float = 40.0, near_m: float = 40.0,
                      lateral_offsets_m: tuple[float, ...] = (), lateral_blend_s: float = 2.0,
                      on_road=None) -> bool:
    """True if some alternative avoids every other agent (see the module docstring).

    `tracks`: a TrafficRecorder's (or a rollout's) `Tracks`; `collision_step` indexes its steps.
    """
    if lateral_offsets_m and on_road is None:
        raise ValueError("lateral alternatives need on_road to keep the ego on the road")
    return any(_clear(tracks, ego, collision_step, dt_s, lookback_s, accel, max_speed_mps,
                      near_m, offset, lateral_blend_s, on_road)
               for offset in (0.0, *lateral_offsets_m) for accel in accels_mps2)


def alternative_track(states: np.ndarray, valid: np.ndarray, ego: int, start: int, steps: int, dt_s: float,
                      accel: float, offset_m: float = 0.0, blend_s: float = 2.0, max_speed_mps: float = 40.0,
                      path_until: int | None = None, turn_heading: bool = True) -> np.ndarray:
    """The ego's states [steps, 6] (x, y, cos, sin, speed, yaw rate) at steps start + 1 ...
    start + steps under one alternative: from its recorded state at `start`, constant
    acceleration `accel` (speed clipped to [0, `max_speed_mps`]) along its own recorded path from
    `start` to `path_until` (default start + steps; straight on past its end), shifted sideways by
    `offset_m` (left positive) blended in with a smoothstep over `blend_s`; with `turn_heading` the
    heading follows the sideways motion, else it stays the path's (the solution check's boxes)."""
    end = min(states.shape[1] - 1, start + steps if path_until is None else path_until)
    path = states[ego, start:end + 1, :2][valid[ego, start:end + 1]]
    speed, travelled = float(states[ego, start, 4]), 0.0
    out = np.zeros((steps, 6))
    for k in range(1, steps + 1):
        new_speed = float(np.clip(speed + accel * dt_s, 0.0, max_speed_mps))
        travelled += 0.5 * (speed + new_speed) * dt_s
        speed = new_speed
        point, direction = _along(path, travelled)    # extends the last segment beyond the end
        if offset_m:
            u = min(1.0, k * dt_s / blend_s)
            left = np.array([-direction[1], direction[0]])
            point = point + offset_m * u * u * (3.0 - 2.0 * u) * left
            if turn_heading:     # the velocity's sideways part: the smoothstep's slope
                slope = offset_m * 6.0 * u * (1.0 - u) / blend_s if u < 1.0 else 0.0
                moving = direction * max(speed, 1e-3) + slope * left
                direction = moving / np.linalg.norm(moving)
        out[k - 1, :2], out[k - 1, 2:4], out[k - 1, 4] = point, direction, speed
    heading = np.unwrap(np.arctan2(np.concatenate([states[ego, start:start + 1, 3], out[:, 3]]),
                                   np.concatenate([states[ego, start:start + 1, 2], out[:, 2]])))
    out[:, 5] = np.diff(heading) / dt_s
    return out


def first_clear_alternative(tracks: Tracks, ego: int, start: int, until: int, dt_s: float,
                            accels_mps2: tuple[float, ...], offsets_m: tuple[float, ...] = (0.0,),
                            blend_s: float = 2.0, max_speed_mps: float = 40.0, near_m: float = 40.0,
                            on_road=None) -> tuple[float, float] | None:
    """(acceleration, offset) of the first alternative (offsets outer, accelerations inner, in
    the order given) whose box overlaps no other agent at any step start + 1 ... `until` and, with
    a sideways offset, stays on the road (`on_road`); None if none does."""
    for offset in offsets_m:
        if offset and on_road is None:
            raise ValueError("lateral alternatives need on_road to keep the ego on the road")
        for accel in accels_mps2:
            if _clear(tracks, ego, until, dt_s, (until - start) * dt_s, accel, max_speed_mps,
                      near_m, offset, blend_s, on_road, path_until=tracks.num_steps - 1):
                return accel, offset
    return None


def safest_clear_alternative(tracks: Tracks, ego: int, start: int, until: int, dt_s: float,
                             accels_mps2: tuple[float, ...], offsets_m: tuple[float, ...] = (0.0,),
                             blend_s: float = 2.0, max_speed_mps: float = 40.0, near_m: float = 40.0,
                             on_road=None) -> tuple[float, float] | None:
    """(acceleration, offset) of the clear alternative (as `first_clear_alternative` judges it)
    that keeps the largest smallest box gap (m) to every other agent within `near_m` over steps
    start + 1 ... `until`; the first in the order given among equals; None if none is clear."""
    best, best_gap = None, -np.inf
    for offset in offsets_m:
        if offset and on_road is None:
            raise ValueError("lateral alternatives need on_road to keep the ego on the road")
        for accel in accels_mps2:
            gaps: list[float] = []
            if _clear(tracks, ego, until, dt_s, (until - start) * dt_s, accel, max_speed_mps,
                      near_m, offset, blend_s, on_road, path_until=tracks.num_steps - 1, gaps=gaps):
                gap = min(gaps, default=np.inf)
                if gap > best_gap:
                    best, best_gap = (accel, offset), gap
    return best


def _clear(tracks: Tracks, ego, collision_step, dt_s, lookback_s, accel, max_speed_mps, near_m,
           offset_m, blend_s, on_road, path_until=None, gaps: list | None = None) -> bool:
    """True if the ego, braking/accelerating at `accel` along its path shifted sideways by
    `offset_m` (blended in over `blend_s`), overlaps no other box and stays on the road, from
    `lookback_s` before `collision_step` to it (its path: up to `path_until`, default the
    collision step). `gaps`, when given, receives the smallest box gap (m) of every step."""
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    start = max(0, collision_step - round(lookback_s / dt_s))
    track = alternative_track(states, valid, ego, start, collision_step - start, dt_s, accel, offset_m, blend_s,
                              max_speed_mps, path_until=collision_step if path_until is None else path_until,
                              turn_heading=False)
    others = [a for a in range(states.shape[0]) if a != ego and valid[a, start:collision_step + 1].any()
              and np.linalg.norm(states[a, start, :2] - states[ego, start, :2]) < near_m + 60.0]
    length, width = sizes[ego]
    for k, state in enumerate(track, start=1):
        point, direction = state[:2], state[2:4]
        if offset_m and not on_road(point, direction, length, width):
            return False
        mine = box_corners(point, direction, length, width)
        step = start + k
        near = []
        for a in others:
            if not valid[a, step] or np.linalg.norm(states[a, step, :2] - point) > near_m:
                continue
            theirs = box_corners(states[a, step, :2], states[a, step, 2:4], *sizes[a])
            if boxes_overlap(mine, theirs):
                return False
            near.append(theirs)
        if gaps is not None:
            gaps.append(min_box_gap(mine, near))
    return True
