"""Per-episode driving metrics of the benchmark (planner paper Table I and more).

Trajectories are world positions [T, 2] (metres) sampled every `dt_s` seconds, starting at the
same time for the ego and the human it is compared with.

Safety (the paper: "the percentage of encounters with neighbouring ado vehicles, across all time
steps, where the ego is dangerously close"): at every step, every ado vehicle whose centre is
within `encounter_radius_m` of the ego's is one encounter; the encounter is dangerous when the
boxes' clearance is under `close_gap_m`, or when the boxes, each moving on at its present speed
and heading, would overlap within `ttc_s` (time to collision under constant velocity, checked
every `ttc_step_s`). Vehicles passing each other in adjacent lanes are therefore not counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.frames import box_corners
from rasterize.geometry import box_gap, boxes_overlap


@dataclass(frozen=True)
class SafetyConfig:
    encounter_radius_m: float = 30.0   # ado centres nearer than this are neighbours
    close_gap_m: float = 1.0           # box clearance below this is dangerously close
    ttc_s: float = 1.5                 # time to collision below this is dangerously close
    ttc_step_s: float = 0.1            # time resolution of the constant-velocity check


def ade_m(ego_xy: np.ndarray, human_xy: np.ndarray) -> float:
    """Mean distance between the two trajectories at equal times, over the human's steps.

    An ego trajectory that ended early (the ego crashed or left the road, which ends the episode)
    stays at its last position for the rest: leaving early must not shorten the comparison.
    """
    ego_xy, human_xy = np.asarray(ego_xy, float), np.asarray(human_xy, float)
    if len(ego_xy) < len(human_xy):
        ego_xy = np.concatenate([ego_xy, np.repeat(ego_xy[-1:], len(human_xy) - len(ego_xy), axis=0)])
    return float(np.linalg.norm(ego_xy[: len(human_xy)] - human_xy, axis=1).mean())


def goal_error_m(ego_xy: np.ndarray, human_xy: np.ndarray) -> float:
    """Distance from where the ego ended to where the human ended (its goal)."""
    return float(np.linalg.norm(np.asarray(ego_xy[-1], float) - np.asarray(human_xy[-1], float)))


def path_length_m(xy: np.ndarray) -> float:
    """Distance driven: the length of the polyline."""
    return float(np.linalg.norm(np.diff(np.asarray(xy, float), axis=0), axis=1).sum())


def mean_jerk_mps3(xy: np.ndarray, dt_s: float) -> float:
    """Mean magnitude of the third time derivative of position (finite differences); 0 if < 4 points."""
    xy = np.asarray(xy, float)
    if len(xy) < 4:
        return 0.0
    jerk = np.diff(xy, n=3, axis=0) / dt_s ** 3
    return float(np.linalg.norm(jerk, axis=1).mean())


def dangerous_encounters(ego: np.ndarray, ego_size: np.ndarray, others: np.ndarray,
                         others_valid: np.ndarray, others_sizes: np.ndarray,
                         config: SafetyConfig = SafetyConfig()) -> tuple[int, int]:
    """(dangerous encounters, encounters) over an episode.

    ego [T, 6] states (x, y, heading_x, heading_y, speed, yaw_rate); others [N, T, 6] with
    validity [N, T]; sizes (length, width) in metres.
    """
    dangerous = total = 0
    for t in range(ego.shape[0]):
        p, h, v = ego[t, :2], ego[t, 2:4], ego[t, 4]
        near = np.flatnonzero(others_valid[:, t] &
                              (np.linalg.norm(others[:, t, :2] - p, axis=1) < config.encounter_radius_m))
        if near.size == 0:
            continue
        me = box_corners(p, h, ego_size[0], ego_size[1])
        for a in near:
            q, g, w = others[a, t, :2], others[a, t, 2:4], others[a, t, 4]
            total += 1
            them = box_corners(q, g, others_sizes[a, 0], others_sizes[a, 1])
            if box_gap(me, them) < config.close_gap_m or _overlap_within(
                    me, v * h, them, w * g, config.ttc_s, config.ttc_step_s):
                dangerous += 1
    return dangerous, total


def _overlap_within(a: np.ndarray, velocity_a: np.ndarray, b: np.ndarray, velocity_b: np.ndarray,
                    horizon_s: float, step_s: float) -> bool:
    """Whether boxes a and b (corners [4, 2]) overlap at some time in (0, horizon] at constant velocity."""
    relative = np.asarray(velocity_b, float) - np.asarray(velocity_a, float)
    reach = 0.5 * (np.ptp(a, axis=0).sum() + np.ptp(b, axis=0).sum())   # > sum of half-diagonals
    offset = b.mean(axis=0) - a.mean(axis=0)
    for t in np.arange(1, round(horizon_s / step_s) + 1) * step_s:
        if np.linalg.norm(offset + t * relative) <= reach and boxes_overlap(a, b + t * relative):
            return True
    return False


def safety_pct(dangerous: int, encounters: int) -> float:
    """Share of encounters that were dangerous, in percent (0 when there were none)."""
    return 100.0 * dangerous / encounters if encounters else 0.0


def summarise_metric(values: list[float]) -> dict:
    """{"mean", "p90", "n"} over finite values (None when there are none)."""
    finite = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=np.float64)
    if finite.size == 0:
        return {"mean": None, "p90": None, "n": 0}
    return {"mean": float(finite.mean()), "p90": float(np.percentile(finite, 90)), "n": int(finite.size)}
