"""Solution check: could the ego alone have avoided a collision that an attack caused?

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


def ego_only_solution(states: np.ndarray, valid: np.ndarray, sizes: np.ndarray, ego: int,
                      collision_step: int, dt_s: float, lookback_s: float = 3.0,
                      accels_mps2: tuple[float, ...] = DEFAULT_ACCELS_MPS2,
                      max_speed_mps: float = 40.0, near_m: float = 40.0,
                      lateral_offsets_m: tuple[float, ...] = (), lateral_blend_s: float = 2.0,
                      on_road=None) -> bool:
    """True if some alternative avoids every other agent (see the module docstring).

    states [A, S, 6] world frame (x, y, cos, sin, speed, yaw rate), valid [A, S], sizes [A, 2]
    (length, width): a TrafficRecorder's arrays; `collision_step` indexes S.
    """
    if lateral_offsets_m and on_road is None:
        raise ValueError("lateral alternatives need on_road to keep the ego on the road")
    return any(_clear(states, valid, sizes, ego, collision_step, dt_s, lookback_s, accel, max_speed_mps,
                      near_m, offset, lateral_blend_s, on_road)
               for offset in (0.0, *lateral_offsets_m) for accel in accels_mps2)


def _clear(states, valid, sizes, ego, collision_step, dt_s, lookback_s, accel, max_speed_mps, near_m,
           offset_m, blend_s, on_road) -> bool:
    """True if the ego, braking/accelerating at `accel` along its path shifted sideways by
    `offset_m` (blended in over `blend_s`), overlaps no other box and stays on the road."""
    start = max(0, collision_step - round(lookback_s / dt_s))
    path = states[ego, start:collision_step + 1, :2][valid[ego, start:collision_step + 1]]
    v0 = float(states[ego, start, 4])
    others = [a for a in range(states.shape[0]) if a != ego and valid[a, start:collision_step + 1].any()
              and np.linalg.norm(states[a, start, :2] - states[ego, start, :2]) < near_m + 60.0]
    length, width = sizes[ego]
    speed, travelled = v0, 0.0
    for k in range(1, collision_step - start + 1):
        new_speed = float(np.clip(speed + accel * dt_s, 0.0, max_speed_mps))
        travelled += 0.5 * (speed + new_speed) * dt_s
        speed = new_speed
        point, direction = _along(path, travelled)    # extends the last segment beyond the end
        if offset_m:
            u = min(1.0, k * dt_s / blend_s)
            point = point + offset_m * u * u * (3.0 - 2.0 * u) * np.array([-direction[1], direction[0]])
            if not on_road(point, direction, length, width):
                return False
        mine = box_corners(point, direction, length, width)
        step = start + k
        for a in others:
            if not valid[a, step] or np.linalg.norm(states[a, step, :2] - point) > near_m:
                continue
            theirs = box_corners(states[a, step, :2], states[a, step, 2:4], *sizes[a])
            if boxes_overlap(mine, theirs):
                return False
    return True
