"""The right-of-way pair test (`_RuleCheck`): one prediction per vehicle, all pair distances at
once, and the rectangle tests whose answer is clear beyond rounding (`_rectangles_known`)."""

from __future__ import annotations

import math

import numpy as np

from riskmap.sim.worlds.fast_road.act_window import _states
from riskmap.sim.worlds.fast_road.tolerances import _TOL_M, _TOL_REL

# The horizon and step `RegulatedRoad.enforce_road_rules` predicts over (is_conflict_possible's
# defaults; `roads` checks them).
_HORIZON, _STEP = 3, 0.25


class _RuleCheck:
    """One `RegulatedRoad.enforce_road_rules` (highway-env's), which asks `is_conflict_possible`
    of every pair of the road's vehicles: is there a predicted time at which the two are within
    the first one's length (a circle test) and their boxes, scaled by 1.5 x 0.9, meet
    (`utils.rotated_rectangles_intersect`)? The answer is a function of the two predicted
    trajectories, and nobody moves during the check (checked at its end), so:

    - each vehicle's trajectory is predicted once (`roads.predict`: the network's batch
      placement for highway-env's `ControlledVehicle` prediction, highway-env's own for
      `Vehicle`'s; vehicles with any other prediction are left to highway-env's function);
    - the distances of all pairs at all times come from one numpy computation; a time whose
      distance is beyond the circle test's limit by more than rounding is not examined, a pair
      with no other time is answered at once, and a pair with a time too near the limit to tell
      is left to highway-env's function;
    - at the other times the rectangles are built from the shared predictions, and tested by
      `_rectangles_known` where the answer is clear beyond rounding, else by highway-env's
      `rotated_rectangles_intersect`.
    """

    __slots__ = ("apart", "index", "intersect", "predict", "predictions", "snapshot",
                 "times_near", "unsure", "vehicles")

    def __init__(self, road, predict, intersect):
        self.vehicles = list(road.vehicles)
        self.index = {id(v): k for k, v in enumerate(self.vehicles)}
        self.snapshot = _states(self.vehicles)
        self.predict = predict        # vehicle -> (positions, headings), or None: not shared
        self.intersect = intersect    # highway-env's utils.rotated_rectangles_intersect
        self.predictions = None       # [k] -> (positions [T, 2], headings) or None
        self.apart = self.unsure = self.times_near = None

    def conflict(self, v1, v2) -> bool | None:
        """`is_conflict_possible(v1, v2)` (default horizon and step) as a bool, or None where
        highway-env's own function must answer."""
        a, b = self.index.get(id(v1)), self.index.get(id(v2))
        if a is None or b is None or self.vehicles[a] is not v1 or self.vehicles[b] is not v2:
            return None
        if self.predictions is None:
            self._prepare()
        if self.apart is None or self.predictions[a] is None or self.predictions[b] is None:
            return None
        if self.apart[a][b]:
            return False
        if self.unsure[a][b]:
            return None
        (positions_1, headings_1), (positions_2, headings_2) = self.predictions[a], self.predictions[b]
        size_1, size_2 = (1.5 * v1.LENGTH, 0.9 * v1.WIDTH), (1.5 * v2.LENGTH, 0.9 * v2.WIDTH)
        for t, distance in self.times_near[a, b]:
            rect_1 = (positions_1[t], *size_1, headings_1[t])
            rect_2 = (positions_2[t], *size_2, headings_2[t])
            overlap = _rectangles_known(rect_1, rect_2, distance)
            if overlap is None:
                overlap = self.intersect(rect_1, rect_2)
            if overlap:
                return True
        return False

    def _prepare(self) -> None:
        times = np.arange(_STEP, _HORIZON, _STEP)
        self.predictions = []
        for v in self.vehicles:
            try:
                prediction = self.predict(v, times)
            except Exception:          # noqa: BLE001 - highway-env's function raises it in turn
                prediction = None
            self.predictions.append(prediction)
        near = _near_in_time(self.vehicles, self.predictions)
        if near is not None:
            self.apart, self.unsure, self.times_near = near

    def unchanged(self) -> bool:
        """Whether nobody moved during the check."""
        return _states(self.vehicles) == self.snapshot


def _near_in_time(vehicles: list, predictions: list):
    """(apart, unsure, times_near) for every ordered pair (a, b) of vehicles with predictions of
    one length: `apart[a][b]` when at every time the distance exceeds a's length by more than
    rounding (the circle test fails throughout); `unsure[a][b]` when at some time it is too near
    that limit to tell; `times_near[a, b]` (read for the others) lists (t, distance) for the times
    at which it is below the limit beyond rounding. None when the predictions cannot be stacked
    (then highway-env's function answers every pair)."""
    rows = [k for k, p in enumerate(predictions) if p is not None]
    try:
        stacked = np.array([np.asarray(predictions[k][0], dtype=np.float64) for k in rows])
        headings = {len(predictions[k][1]) for k in rows}
        limits = np.array([float(v.LENGTH) for v in vehicles], dtype=np.float64)
    except (TypeError, ValueError, AttributeError):
        return None
    if not rows or stacked.ndim != 3 or stacked.shape[2] != 2 or headings != {stacked.shape[1]}:
        return None
    n = len(vehicles)
    delta = stacked[None, :, :, :] - stacked[:, None, :, :]
    distance = np.sqrt((delta * delta).sum(axis=-1))               # [i, j, time] over `rows`
    limit = limits[rows][:, None, None]
    tol = _TOL_M + _TOL_REL * distance
    far, near = distance > limit + tol, distance < limit - tol
    sub_apart, sub_unsure = far.all(axis=-1).tolist(), (~far & ~near).any(axis=-1).tolist()
    apart = [[False] * n for _ in range(n)]
    unsure = [[True] * n for _ in range(n)]
    for i, a in enumerate(rows):
        for j, b in enumerate(rows):
            apart[a][b], unsure[a][b] = sub_apart[i][j], sub_unsure[i][j]
    times_near = _TimesNear(rows, near, distance)
    return apart, unsure, times_near


class _TimesNear:
    """(t, distance) of the times at which a pair is within the circle test's limit, listed on
    first use."""

    __slots__ = ("distance", "found", "near", "position")

    def __init__(self, rows: list, near: np.ndarray, distance: np.ndarray):
        self.position = {k: i for i, k in enumerate(rows)}
        self.near, self.distance, self.found = near, distance, {}

    def __getitem__(self, pair: tuple[int, int]) -> list:
        found = self.found.get(pair)
        if found is None:
            i, j = self.position[pair[0]], self.position[pair[1]]
            times = np.flatnonzero(self.near[i, j]).tolist()
            found = self.found[pair] = [(t, float(self.distance[i, j, t])) for t in times]
        return found


def _rectangles_known(rect_1, rect_2, distance: float) -> bool | None:
    """What highway-env's `rotated_rectangles_intersect(rect_1, rect_2)` answers where that is
    clear beyond rounding, else None (then it must be asked).

    It tests whether one of the 9 points (corners, edge midpoints, centre) of either rectangle,
    placed at its angle, passes `point_in_rotated_rectangle` of the other, whose region is the
    other's box turned by minus its angle (the test rotates the offset by +angle). True: a centre
    lies in the other's inscribed circle (which no turn moves). False: each rectangle is apart
    from the other's region along one of their four axes."""
    try:
        (p1, l1, w1, h1), (p2, l2, w2, h2) = rect_1, rect_2
        l1, w1, h1, l2, w2, h2 = map(float, (l1, w1, h1, l2, w2, h2))
        dx, dy = float(p2[0]) - float(p1[0]), float(p2[1]) - float(p1[1])
    except (TypeError, ValueError, IndexError):
        return None
    if not all(map(math.isfinite, (l1, w1, h1, l2, w2, h2, dx, dy, distance))) \
            or min(l1, w1, l2, w2) <= 0:
        return None
    tol = _TOL_M + _TOL_REL * (abs(float(p1[0])) + abs(float(p1[1])) + l1 + l2)
    if distance < min(l1, w1, l2, w2) / 2 - tol:
        return True
    if _apart(dx, dy, l1, w1, h1, l2, w2, -h2, tol) and _apart(dx, dy, l2, w2, h2, l1, w1, -h1, tol):
        return False
    return None


def _apart(dx: float, dy: float, la: float, wa: float, ha: float, lb: float, wb: float,
           hb: float, tol: float) -> bool:
    """Whether boxes A (la x wa at angle ha) and B (lb x wb at angle hb), centres `(dx, dy)`
    apart, are separated by more than `tol` along one of their four axes."""
    ca, sa, cb, sb = math.cos(ha), math.sin(ha), math.cos(hb), math.sin(hb)
    cr, sr = abs(ca * cb + sa * sb), abs(sa * cb - ca * sb)        # |cos|, |sin| of ha - hb
    for ux, uy, half_a, half_b in ((ca, sa, la / 2, (lb * cr + wb * sr) / 2),
                                   (-sa, ca, wa / 2, (lb * sr + wb * cr) / 2),
                                   (cb, sb, (la * cr + wa * sr) / 2, lb / 2),
                                   (-sb, cb, (la * sr + wa * cr) / 2, wb / 2)):
        if abs(dx * ux + dy * uy) - half_a - half_b > tol:
            return True
    return False
