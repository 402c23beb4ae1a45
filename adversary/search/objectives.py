"""Objectives and constraint of the scenario search (the black-box search paper, §5.5.2).

Objectives (pymoo minimises every column of F):
    f1 = −journey distance: Euclidean distance from the ego's first to its last position
         (the paper maximises it: an ego that did not stop in time travelled far);
    f2 = Σ_t distance(ego, target) over the control steps (centre to centre, metres);
    f3 = scene alteration: Σ_i |p_i − neutral_i| / (high_i − low_i), the normalised deviation of
         every parameter from the base scene.

The collision flag. The paper multiplies the objectives by Collision() ∈ {−1000, 0}. Taken
literally every collision-free scene scores 0 on all three objectives (no guidance at all), and
among colliding scenes the multiplication by a negative number reverses what "better" means for
the minimised objectives. We make it well defined as an additive, lexicographic penalty:
each objective is first scaled into [0, 1] (f̂1 = 1 − journey / journey_max,
f̂2 = Σ_t d_t / (steps_max · distance_max), f̂3 = alteration / n_params; clipped), then

    F_i = f̂_i − 1000 · collided.

So every colliding scene dominates every collision-free one in every objective (the flag's
weight is far larger than any scaled objective can differ), while within each group the paper's
three objectives still rank the scenes and guide the search towards failures.

Constraint (pymoo: G ≤ 0 is feasible): the initial gap must be at least the distance the ego
needs to brake down to the target's final speed, less the distance the target itself covers
while braking to that speed, both from v1² = v0² + 2as with a = −deceleration:

    G = max(0, (v_ego² − v_f²) / (2 a_ego)) − (v_target² − v_f²) / (2 a_target) − gap.

With a static target (the paper's pedestrian, v_target = v_f = 0) this is the paper's rule
"gap ≥ braking distance". Reaction time is ignored: the scene is solvable in principle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.errors import InputError

COLLISION_PENALTY = 1000.0


def braking_distance_m(v0_mps: float, v1_mps: float, decel_mps2: float) -> float:
    """Distance to go from v0 to v1 ≤ v0 at constant deceleration: s from v1² = v0² + 2as, a = −decel."""
    if v1_mps > v0_mps:
        raise InputError(f"braking from {v0_mps} m/s cannot end at a higher {v1_mps} m/s")
    if v1_mps == v0_mps:
        return 0.0
    if decel_mps2 <= 0:
        raise InputError(f"deceleration must be positive m/s², got {decel_mps2}")
    a = -decel_mps2
    return (v1_mps ** 2 - v0_mps ** 2) / (2.0 * a)


def required_gap_m(ego_speed_mps: float, ego_brake_mps2: float, target_speed_mps: float,
                   target_final_speed_mps: float, target_brake_mps2: float) -> float:
    """Smallest initial gap from which the ego can still brake to the target's final speed."""
    v_f = target_final_speed_mps
    ego_needs = braking_distance_m(ego_speed_mps, v_f, ego_brake_mps2) if ego_speed_mps > v_f else 0.0
    target_covers = braking_distance_m(target_speed_mps, v_f, target_brake_mps2)
    return ego_needs - target_covers


def scene_alteration(values: np.ndarray, neutral: np.ndarray, lower: np.ndarray,
                     upper: np.ndarray) -> float:
    """Σ_i |p_i − neutral_i| / (upper_i − lower_i) (0 for the base scene)."""
    return float(np.sum(np.abs(np.asarray(values) - neutral) / (upper - lower)))


def journey_distance_m(ego_xy: np.ndarray) -> float:
    """Euclidean distance from the first to the last ego position; ego_xy [T, 2]."""
    return float(np.linalg.norm(ego_xy[-1] - ego_xy[0]))


def total_distance_m(ego_xy: np.ndarray, target_xy: np.ndarray) -> float:
    """Σ_t ‖ego_t − target_t‖ over the steps of the episode; both [T, 2]."""
    return float(np.linalg.norm(ego_xy - target_xy, axis=1).sum())


@dataclass(frozen=True)
class ObjectiveScales:
    """Scales that map the raw objectives into [0, 1]."""

    journey_max_m: float          # the farthest the ego can get in one episode
    steps_max: int                # control steps of a full episode
    distance_max_m: float = 200.0  # distances to the target above this count as this
    n_params: int = 1


def penalised_objectives(journey_m: float, total_m: float, alteration: float, collided: bool,
                         scales: ObjectiveScales) -> np.ndarray:
    """F [3] for pymoo: scaled objectives minus the collision penalty (module docstring)."""
    f = np.array([1.0 - journey_m / scales.journey_max_m,
                  total_m / (scales.steps_max * scales.distance_max_m),
                  alteration / scales.n_params])
    return np.clip(f, 0.0, 1.0) - COLLISION_PENALTY * float(collided)


# Names of the columns of F (scaled as in `penalised_objectives`, all minimised).
OBJECTIVE_NAMES = ("f1 = 1 − journey / longest journey", "f2 = Σ distance to target (scaled)",
                   "f3 = scene alteration (scaled)")


def collided_from_objectives(F: np.ndarray) -> np.ndarray:
    """The collision flag of penalised objective rows F [..., 3] -> [...] bool: scaled objectives
    lie in [0, 1], so only a collision's penalty takes them below −COLLISION_PENALTY / 2."""
    return np.asarray(F)[..., 0] < -0.5 * COLLISION_PENALTY


def unpenalised(F: np.ndarray) -> np.ndarray:
    """The scaled objectives of penalised rows F [..., 3] (the collision penalty taken back off)."""
    F = np.asarray(F, dtype=np.float64)
    return F + COLLISION_PENALTY * collided_from_objectives(F)[..., None]
