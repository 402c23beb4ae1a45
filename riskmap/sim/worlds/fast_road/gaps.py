"""The smallest gap around the ego on a fast road (`min_gap_on_road`), nearest boxes first."""

from __future__ import annotations

import math

import numpy as np

from riskmap.sim.worlds.fast_road.tolerances import _TOL_M, _TOL_REL


def min_gap_on_road(road, ego, radius_m: float) -> float:
    """`riskmap.sim.worlds.episode.min_gap_on_road`, the same value. Box gaps are measured in the order
    of a lower bound (the larger of the centre distance less both half diagonals and the boxes'
    separation along the ego's two axes), and only while that bound does not exceed the smallest
    gap found so far."""
    from riskmap.sim.records.metrics import box_gap, vehicle_box

    try:
        ex, ey = float(ego.position[0]), float(ego.position[1])
        heading, length, width = float(ego.heading), float(ego.LENGTH), float(ego.WIDTH)
        near = []
        for v in road.vehicles:
            if v is ego:
                continue
            dx, dy = float(v.position[0]) - ex, float(v.position[1]) - ey
            distance = math.hypot(dx, dy)
            margin = _TOL_M + _TOL_REL * (distance + abs(ex) + abs(ey))
            if not (distance < radius_m + margin):      # also NaN: measured the reference way
                if not math.isnan(distance):
                    continue
                return _min_gap_reference(road, ego, radius_m)
            if distance > radius_m - margin and not \
                    np.linalg.norm(v.position - ego.position) < radius_m:
                continue
            near.append((v, dx, dy, distance, margin))
    except (TypeError, ValueError, AttributeError, IndexError):
        return _min_gap_reference(road, ego, radius_m)
    if not near:
        return float("inf")
    c, s = math.cos(heading), math.sin(heading)
    bounded = []
    for v, dx, dy, distance, margin in near:
        l_v, w_v, relative = float(v.LENGTH), float(v.WIDTH), float(v.heading) - heading
        cos_r, sin_r = abs(math.cos(relative)), abs(math.sin(relative))
        # Separation along the ego's axes (two of the axes box_gap's overlap test tries).
        apart = max(abs(dx * c + dy * s) - 0.5 * (length + l_v * cos_r + w_v * sin_r),
                    abs(-dx * s + dy * c) - 0.5 * (width + l_v * sin_r + w_v * cos_r)) - margin
        lower = max(distance - 0.5 * math.hypot(l_v, w_v) - 0.5 * math.hypot(length, width)
                    - margin, apart)
        if not math.isfinite(lower):
            return _min_gap_reference(road, ego, radius_m)
        bounded.append((lower, apart > 0, v))
    box = vehicle_box(ego)
    best = float("inf")
    for lower, separated, v in sorted(bounded, key=lambda item: item[0]):
        if lower > best:
            break
        best = min(best, box_gap(box, vehicle_box(v), separated=separated))
    return float(best)


def _min_gap_reference(road, ego, radius_m: float) -> float:
    from riskmap.sim.records.metrics import min_box_gap, vehicle_box

    return min_box_gap(vehicle_box(ego), (vehicle_box(v) for v in road.vehicles
                                          if v is not ego and np.linalg.norm(v.position - ego.position) < radius_m))
