"""The closest-lane search (`_LaneFinder`): lanes visited in the order of a lower bound of their
distance, only those that may be the closest measured by highway-env."""

from __future__ import annotations

import math

import numpy as np

from riskmap.sim.worlds.fast_road.tolerances import _TOL_M, _TOL_REL


def _lane_bounds(lane, straight, sine, circular) -> tuple[float, float, float, float, float] | None:
    """(xmin, xmax, ymin, ymax, slack) such that highway-env's `distance_with_heading` from any
    point to `lane` is at least the point's distance to the box less `slack`; None when unknown
    (such a lane is always measured).

    Straight: |lateral| + the overshoot beyond either end >= the Euclidean distance to the
    centre segment >= the distance to its box. Sine: its lateral is the straight one less at
    most |amplitude|. Circular: |radius - r| + the arc overshoot >= the distance to the arc
    (a chord is no longer than its arc) >= the distance to the circle's box. The heading term
    is never negative.
    """
    kind = type(lane)
    if kind is straight or kind is sine:
        start, end = np.asarray(lane.start, dtype=float), np.asarray(lane.end, dtype=float)
        slack = abs(float(lane.amplitude)) if kind is sine else 0.0
        ok = (start.shape == (2,) and end.shape == (2,) and np.isfinite(start).all()
              and np.isfinite(end).all() and np.isfinite(slack) and float(lane.length) > 0
              and np.isfinite(np.asarray(lane.direction, dtype=float)).all())
        if not ok:
            return None
        return (min(start[0], end[0]), max(start[0], end[0]), min(start[1], end[1]),
                max(start[1], end[1]), slack)
    if kind is circular:
        centre, radius = np.asarray(lane.center, dtype=float), float(lane.radius)
        if not (centre.shape == (2,) and np.isfinite(centre).all() and np.isfinite(radius)
                and radius > 0 and np.isfinite(float(lane.length))):
            return None
        return (centre[0] - radius, centre[0] + radius, centre[1] - radius, centre[1] + radius, 0.0)
    return None


def _wrap(x: float) -> float:
    return ((x + math.pi) % (2 * math.pi)) - math.pi


class _LaneFinder:
    """The closest-lane search over one network's lanes (`entries`: [(index, lane)] in the
    network's order), giving `RoadNetwork.get_closest_lane_index`'s answer.

    Lanes are visited in the order of a lower bound of their distance (the distance from the
    point, or with many lanes from its grid cell, to the lane's box, `_lane_bounds`), and
    approximated where the lane's formulas are known (straight and circular lanes; float
    arithmetic, within a rounding margin of highway-env's value: `_TOL_M` plus `_TOL_REL` of the
    coordinates involved); the visit stops at the first lane whose bound exceeds the smallest
    upper bound found. Only the lanes that may then be the closest are measured by highway-env's
    own `distance_with_heading`, and the first smallest of them is the answer, as in highway-env.

    It also holds the straight and circular lanes' geometry (`straight_lanes`,
    `circular_lanes`) for the act window's test of which vehicles may be on a lane.
    """

    CELL_M = 2.0
    FEW_LANES = 8

    def __init__(self, entries: list, straight, sine, circular):
        self.entries = entries
        self.bounds = [_lane_bounds(lane, straight, sine, circular) for _, lane in entries]
        self.params = [_approx_params(lane, straight, circular) for _, lane in entries]
        self.scales = [0.0 if p is None else 8 * sum(abs(v) for v in p[1:]) for p in self.params]
        self.cells: dict = {}
        # Straight lanes: start, direction, lateral direction, length and on_lane's limits.
        self.straight_lanes: dict = {}                # lane -> (sx, sy, d0, d1, l0, l1, length,
        for (_, lane), p in zip(entries, self.params):  # half width + 1, vehicle length)
            if p is not None and p[0] == "straight":
                try:
                    limits = (float(lane.width) / 2 + 1, float(lane.VEHICLE_LENGTH))
                except (TypeError, ValueError, AttributeError):
                    continue
                if all(map(math.isfinite, limits)):
                    self.straight_lanes[lane] = (*p[1:8], *limits)
        # Circular lanes: centre, radius and on_lane's lateral limit.
        self.circular_lanes: dict = {}                # lane -> (cx, cy, radius, half width + 1)
        for (_, lane), p in zip(entries, self.params):
            if p is not None and p[0] == "circular":
                try:
                    limit = float(lane.width) / 2 + 1
                except (TypeError, ValueError, AttributeError):
                    continue
                if math.isfinite(limit):
                    self.circular_lanes[lane] = (*p[1:4], limit)

    def _order(self, x0: float, y0: float, x1: float, y1: float) -> list:
        """[(lower bound, k)] sorted: a lower bound of the distance from any point of the box
        [x0, x1] x [y0, y1] to lane k."""
        order = []
        for k, b in enumerate(self.bounds):
            if b is None:
                order.append((-math.inf, k))
                continue
            xmin, xmax, ymin, ymax, slack = b
            gx = max(xmin - x1, x0 - xmax, 0.0)
            gy = max(ymin - y1, y0 - ymax, 0.0)
            order.append((math.hypot(gx, gy) - slack - _TOL_M, k))
        order.sort()
        return order

    def _cell(self, key: tuple[int, int]) -> list:
        x0, y0 = key[0] * self.CELL_M, key[1] * self.CELL_M
        order = self.cells[key] = self._order(x0, y0, x0 + self.CELL_M, y0 + self.CELL_M)
        return order

    def closest(self, position, heading):
        """The closest lane's index, or None where highway-env's own search must answer (a
        non-finite point or heading, or a lane measured as non-finite)."""
        try:
            x, y = float(position[0]), float(position[1])
            h = None if heading is None else float(heading)
        except (TypeError, IndexError, ValueError):
            return None
        if not (math.isfinite(x) and math.isfinite(y) and (h is None or math.isfinite(h))):
            return None
        if len(self.entries) <= self.FEW_LANES:             # bounds of the point itself
            order = self._order(x, y, x, y)
        else:                                               # cached bounds of its grid cell
            key = (math.floor(x / self.CELL_M), math.floor(y / self.CELL_M))
            order = self.cells.get(key) or self._cell(key)
        entries, params = self.entries, self.params
        upper, maybe, exact = math.inf, [], {}
        for lower, k in order:
            if lower > upper:
                break
            p = params[k]
            a = None if p is None else _approx_distance(p, x, y, h)
            if a is None:
                d = entries[k][1].distance_with_heading(position, heading)
                if not math.isfinite(d):
                    return None
                exact[k] = d
                maybe.append((k, d))
                upper = min(upper, d)
            else:
                e = _TOL_M + _TOL_REL * (abs(x) + abs(y) + self.scales[k])
                maybe.append((k, a - e))
                upper = min(upper, a + e)
        keep = sorted(k for k, low in maybe if low <= upper)
        if len(keep) == 1:
            return entries[keep[0]][0]
        distances = [exact[k] if k in exact else entries[k][1].distance_with_heading(position, heading)
                     for k in keep]
        if not all(math.isfinite(d) for d in distances):
            return None
        return entries[keep[_argmin(distances)]][0]


def _approx_params(lane, straight, circular):
    """What `_approx_distance` needs of a straight or circular lane; None for other lanes."""
    kind = type(lane)
    try:
        if kind is straight:
            values = (*map(float, lane.start), *map(float, lane.direction),
                      *map(float, lane.direction_lateral), float(lane.length), float(lane.heading))
            if len(values) == 8 and all(math.isfinite(v) for v in values) and values[6] > 0:
                return ("straight", *values)
        elif kind is circular:
            values = (*map(float, lane.center), float(lane.radius), float(lane.start_phase),
                      float(lane.direction), float(lane.length))
            if len(values) == 6 and all(math.isfinite(v) for v in values) and values[2] > 0:
                return ("circular", *values)
    except (TypeError, ValueError):
        return None
    return None


def _approx_distance(p, x: float, y: float, heading: float | None) -> float | None:
    """highway-env's `distance_with_heading` of a straight or circular lane, in floats (up to
    rounding); None near a circular lane's phase wrap, where rounding may jump."""
    if p[0] == "straight":
        _, sx, sy, d0, d1, l0, l1, length, lane_heading = p
        dx, dy = x - sx, y - sy
        s = dx * d0 + dy * d1
        r = dx * l0 + dy * l1
    else:
        _, cx, cy, radius, start, direction, length = p
        dx, dy = x - cx, y - cy
        w = _wrap(math.atan2(dy, dx) - start)
        if abs(w) > math.pi - 1e-6:
            return None
        s = direction * w * radius
        r = direction * (radius - math.hypot(dx, dy))
        lane_heading = direction * s / radius + start + math.pi / 2 * direction
    distance = abs(r) + max(s - length, 0.0) + max(0.0 - s, 0.0)
    if heading is not None:
        distance += abs(_wrap(heading - lane_heading))
    return distance


def _argmin(values: list) -> int:
    """`int(np.argmin(values))`: the first smallest, or the first NaN if there is one."""
    if any(math.isnan(v) for v in values):
        return int(np.argmin(values))
    best = 0
    for k in range(1, len(values)):
        if values[k] < values[best]:
            best = k
    return best
