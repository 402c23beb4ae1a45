"""Oriented-box geometry: overlap and clearance between vehicles' boxes (corners [4, 2])."""

from __future__ import annotations

import numpy as np


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
