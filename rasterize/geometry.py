"""Plane geometry in world metres: polylines (`Polyline`, `arc_lengths`, `drop_repeats`) and
oriented boxes (overlap and clearance between vehicles' boxes, corners [4, 2])."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from rasterize.errors import InputError


# --- polylines -----------------------------------------------------------------------------------

def arc_lengths(points: np.ndarray) -> np.ndarray:
    """Cumulative arc length [N] (m) at each point of a polyline [N, 2]: 0 at the first point.
    Repeated points add nothing; any N >= 1 and the points' own dtype (no checks)."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def drop_repeats(points: np.ndarray, min_step_m: float = 1e-6) -> np.ndarray:
    """The points [K <= N, 2] of `points` [N, 2] without each point that lies within `min_step_m`
    of the point before it in `points` (the first point always stays; K may be below 2). A NaN
    point and the one after it compare False, so they are dropped too."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1) > min_step_m])
    return points[keep]


@dataclass(frozen=True, eq=False)
class Polyline:
    """A polyline in world metres and arc length along it.

        points    [N, 2]    float64, N >= 2, finite (repeated points allowed: see `drop_repeats`)
        segments  [N-1, 2]  points[k + 1] - points[k]
        lengths   [N-1]     |segments[k]|
        arc       [N]       start_m + cumulative arc length at each point (`arc_lengths`)
        length              arc[-1] - arc[0]

    `start_m` is the arc length of the first point, for a piece of a longer line (a lane's
    boundary whose dashes keep their phase). Positions at arc lengths come two ways:
    `point_at` interpolates x and y (np.interp) and stays at the end points past either end
    (or runs straight on past the last one along a given direction); `pose_at` also gives the
    unit tangent and runs straight on along the end segments past both ends (needs segments of
    nonzero length: build it from `drop_repeats(points)`).
    """

    points: np.ndarray
    start_m: float = 0.0

    def __post_init__(self) -> None:
        points = np.asarray(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 2 or points.shape[0] < 2:
            raise InputError(f"a polyline needs points of shape [N>=2, 2], got {points.shape}")
        finite = np.isfinite(points).all(axis=1)
        if not finite.all():
            raise InputError(f"a polyline's points must be finite; point {int(np.argmin(finite))} "
                             "is NaN or inf")
        object.__setattr__(self, "points", points)

    @cached_property
    def segments(self) -> np.ndarray:
        return np.diff(self.points, axis=0)

    @cached_property
    def lengths(self) -> np.ndarray:
        return np.linalg.norm(self.segments, axis=1)

    @cached_property
    def arc(self) -> np.ndarray:
        return self.start_m + np.concatenate([[0.0], np.cumsum(self.lengths)])

    @cached_property
    def tangents(self) -> np.ndarray:
        """Unit directions [N-1, 2] of the segments."""
        return self.segments / self.lengths[:, None]

    @property
    def length(self) -> float:
        return float(self.arc[-1] - self.arc[0])

    def point_at(self, arc_m, beyond: np.ndarray | None = None) -> np.ndarray:
        """Points [..., 2] at arc lengths `arc_m` [...] (a scalar gives [2]), x and y interpolated
        separately; before the start the first point, past the end the last one, or with
        `beyond` (a direction [2]) the last point + (arc_m - arc[-1]) * beyond."""
        arc_m = np.asarray(arc_m, dtype=np.float64)
        out = np.stack([np.interp(arc_m, self.arc, self.points[:, 0]),
                        np.interp(arc_m, self.arc, self.points[:, 1])], axis=-1)
        if beyond is None:
            return out
        ahead = self.points[-1] + (arc_m - self.arc[-1])[..., None] * np.asarray(beyond)
        return np.where((arc_m > self.arc[-1])[..., None], ahead, out)

    def pose_at(self, arc_m) -> tuple[np.ndarray, np.ndarray]:
        """Points [M, 2] and unit tangents [M, 2] at arc lengths [M] (a scalar counts as [1]); past
        either end the line runs straight on along its end segment."""
        arc_m = np.asarray(arc_m, dtype=np.float64).reshape(-1)
        k = np.clip(np.searchsorted(self.arc, arc_m, side="right") - 1, 0, len(self.lengths) - 1)
        return self.points[k] + (arc_m - self.arc[k])[:, None] * self.tangents[k], self.tangents[k]

    def project(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arc length [P] and signed lateral offset [P] (m, left positive) of points [P, 2] (or
        one point [2]) on the line run straight on past both ends (as `pose_at`)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        rel = xy[:, None, :] - self.points[None, :-1]
        along = np.einsum("pkd,kd->pk", rel, self.tangents)
        low = np.full(len(self.lengths), 0.0)
        high = self.lengths.copy()
        low[0], high[-1] = -np.inf, np.inf           # the straight continuations
        along = np.clip(along, low, high)
        foot = self.points[None, :-1] + along[..., None] * self.tangents[None]
        k = np.argmin(np.linalg.norm(xy[:, None, :] - foot, axis=2), axis=1)
        rows = np.arange(len(xy))
        t = self.tangents[k]
        d = xy - foot[rows, k]
        return self.arc[k] + along[rows, k], t[:, 0] * d[:, 1] - t[:, 1] * d[:, 0]

    def nearest(self, point: np.ndarray) -> tuple[int, float, float]:
        """The nearest point of the line (not run on past its ends) to `point` [2]: its segment k,
        its fraction along that segment in [0, 1], and its distance (m); ties go to the first
        segment. Squared segment lengths are floored at 1e-12 m² (a repeated point's segment gives
        fraction 0)."""
        a, ab = self.points[:-1], self.segments
        t = np.clip(((point - a) * ab).sum(axis=1) / np.maximum((ab * ab).sum(axis=1), 1e-12), 0, 1)
        distance = np.linalg.norm(a + t[:, None] * ab - point, axis=1)
        k = int(np.argmin(distance))
        return k, float(t[k]), float(distance[k])


# --- oriented boxes ------------------------------------------------------------------------------


def _axes(corners: np.ndarray) -> np.ndarray:
    edges = np.roll(corners, -1, axis=0) - corners
    normals = np.stack([-edges[:, 1], edges[:, 0]], axis=1)
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)


def boxes_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex quadrilaterals."""
    for axis in np.concatenate([_axes(a), _axes(b)]):
        pa, pb = a @ axis, b @ axis
        if pa.max() < pb.min() or pb.max() < pa.min():
            return False
    return True


def _point_segment_distance(p: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
    """Distances [P, S] from points [P, 2] to segments (s0, s1) [S, 2]."""
    d = s1 - s0
    t = ((p[:, None, :] - s0[None]) * d[None]).sum(-1) / np.maximum((d * d).sum(-1), 1e-12)
    closest = s0[None] + np.clip(t, 0.0, 1.0)[..., None] * d[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=-1)


def box_gap(a: np.ndarray, b: np.ndarray, separated: bool = False) -> float:
    """Clearance (m) between two boxes: 0 when they touch or overlap. `separated`: the caller
    knows that `boxes_overlap(a, b)` is False (the boxes are apart by more than rounding along
    an axis it tests), so the test is skipped; the value is the same."""
    if separated:
        return _separated_gap(a, b)
    if boxes_overlap(a, b):
        return 0.0
    ea0, ea1 = a, np.roll(a, -1, axis=0)
    eb0, eb1 = b, np.roll(b, -1, axis=0)
    return float(min(_point_segment_distance(a, eb0, eb1).min(),
                     _point_segment_distance(b, ea0, ea1).min()))


def _separated_gap(a: np.ndarray, b: np.ndarray) -> float:
    """`box_gap`'s distance part, both directions in one pass: the corners of a against the
    edges of b and the corners of b against the edges of a, with `_point_segment_distance`'s
    elementwise operations (over a leading axis of 2), so the smallest value is the same."""
    order = [1, 2, 3, 0]                                   # np.roll(corners, -1, axis=0)
    p = np.stack([a, b])                                    # [2, 4, 2] corners
    s0 = np.stack([b, a])                                   # [2, 4, 2] edge starts
    s1 = np.stack([b[order], a[order]])
    d = s1 - s0
    t = ((p[:, :, None, :] - s0[:, None]) * d[:, None]).sum(-1) / np.maximum(
        (d * d).sum(-1), 1e-12)[:, None, :]
    closest = s0[:, None] + np.clip(t, 0.0, 1.0)[..., None] * d[:, None]
    return float(np.linalg.norm(p[:, :, None, :] - closest, axis=-1).min())
