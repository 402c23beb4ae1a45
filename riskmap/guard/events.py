"""Interaction events: the minimum projected separation d_s between two oriented boxes.

d_s = d − (s1 + s2), with d the distance between the box centres and, for each vehicle,
s(φ) = l/2·|cos φ| + w/2·|sin φ|, φ the angle between the line of centres and its yaw: the
half-extent of the box along the line of centres. d_s < 0 means the boxes overlap along that
line (a collision, or about to be one).

Shapes: any common broadcast shape `...`; centres [..., 2] (m), yaw [...] (rad), sizes [..., 2]
(length, width in m).
"""

from __future__ import annotations

import numpy as np

from rasterize.scene import Scene
from rasterize.tracks import Tracks


def half_extent_along(direction_rad: np.ndarray, yaw_rad: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """s(φ) = l/2·|cos φ| + w/2·|sin φ| with φ = direction − yaw, metres [...]."""
    phi = np.asarray(direction_rad, dtype=np.float64) - np.asarray(yaw_rad, dtype=np.float64)
    sizes = np.asarray(sizes, dtype=np.float64)
    return 0.5 * sizes[..., 0] * np.abs(np.cos(phi)) + 0.5 * sizes[..., 1] * np.abs(np.sin(phi))


def projected_separation(centre_a: np.ndarray, yaw_a: np.ndarray, size_a: np.ndarray,
                         centre_b: np.ndarray, yaw_b: np.ndarray, size_b: np.ndarray) -> np.ndarray:
    """d_s between boxes a and b, metres [...]. Coincident centres use φ = yaw (s = l/2)."""
    delta = np.asarray(centre_b, dtype=np.float64) - np.asarray(centre_a, dtype=np.float64)
    d = np.linalg.norm(delta, axis=-1)
    # The direction of the line of centres; when the centres coincide there is none, and a's
    # heading stands in for it.
    direction = np.where(d > 1e-9, np.arctan2(delta[..., 1], delta[..., 0]),
                         np.broadcast_to(np.asarray(yaw_a, dtype=np.float64), d.shape))
    return d - half_extent_along(direction, yaw_a, size_a) - half_extent_along(direction, yaw_b, size_b)


def scene_separations(tracks: Tracks, ego: int) -> np.ndarray:
    """d_s between the ego and every agent at every step, [A, S] metres (inf where either is absent
    and for the ego itself)."""
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    yaw = np.arctan2(states[..., 3], states[..., 2])
    ds = projected_separation(states[ego:ego + 1, :, :2], yaw[ego:ego + 1], sizes[ego][None, None],
                              states[..., :2], yaw, sizes[:, None, :])
    present = valid & valid[ego][None, :]
    present[ego] = False
    return np.where(present, ds, np.inf)


def nearest_by_separation(ds: np.ndarray, count: int) -> list[int]:
    """Indices of the `count` smallest finite d_s [N] (fewer if absent)."""
    order = np.argsort(ds, kind="stable")
    return [int(i) for i in order[:count] if np.isfinite(ds[i])]


def nearest_neighbours(scene: Scene, count: int = 2) -> list[int]:
    """Indices of the `count` agents with the smallest d_s to the ego now (fewer if absent)."""
    now = scene.current_index
    ds = scene_separations(Tracks(scene.states[:, now:now + 1], scene.valid[:, now:now + 1], scene.sizes,
                                  scene.kinds), scene.ego_index)[:, 0]
    return nearest_by_separation(ds, count)
