"""The collision prefilter: the pairs whose bounding circles may meet (`_collision_candidates`)."""

from __future__ import annotations

import math

from riskmap.sim.worlds.fast_road.tolerances import _TOL_M, _TOL_REL


def _collision_candidates(vehicles: list, members: list, dt: float) -> list | None:
    """(i, j) index pairs, in highway-env's order, whose collision check cannot be skipped: i a
    vehicle, j > i a vehicle or j >= len(vehicles) an object (`members` = vehicles + objects).
    None when the prefilter does not apply (then every pair is checked).

    highway-env's check returns at once when |p_j - p_i| > (diag_i + diag_j) / 2 + speed_i * dt;
    pairs are swept in the order of x, and a pair is kept unless that holds by more than a
    rounding margin."""
    n = len(vehicles)
    try:
        xy = [m.position.tolist() for m in members]
        diagonals = [float(m.diagonal) for m in members]
        speeds = [float(v.speed) for v in vehicles]
    except (AttributeError, TypeError, ValueError):
        return None
    if not all(len(p) == 2 and math.isfinite(p[0]) and math.isfinite(p[1]) for p in xy) or not (
            all(map(math.isfinite, diagonals)) and all(map(math.isfinite, speeds))):
        return None
    reach = max(diagonals) + max(0.0, max(speeds, default=0.0)) * dt
    order = sorted(range(len(members)), key=lambda k: xy[k][0])
    pairs = []
    for a, i in enumerate(order):
        xi = xy[i][0]
        for j in order[a + 1:]:
            if xy[j][0] - xi > reach + _TOL_M + _TOL_REL * abs(xi):
                break
            first, second = (i, j) if i < j else (j, i)
            if first >= n:
                continue                                  # two objects: never checked
            dx, dy = xy[second][0] - xy[first][0], xy[second][1] - xy[first][1]
            distance = math.hypot(dx, dy)
            threshold = (diagonals[first] + diagonals[second]) / 2 + speeds[first] * dt
            if distance > threshold + _TOL_M + _TOL_REL * (abs(xi) + abs(xy[i][1]) + distance):
                continue
            pairs.append((first, second))
    pairs.sort()
    return pairs
