"""The Intelligent Driver Model (Treiber, Hennecke and Helbing 2000): the one longitudinal law.

Both IDM users call these two functions with their own parameters: the reactive recorded
traffic (`riskmap.sim.drivers.reactive_traffic.IdmParams`) and the `idm` baseline on recordings
(`riskmap.sim.drivers.recorded_idm.idm_accel`).

    s*(v, dv) = s0 + max(0, v T + v dv / (2 sqrt(a b)))              desired gap
    dv/dt     = max(-b_max, a [1 - (v / v0)^delta - (s* / s)^2])     acceleration

with v the follower's speed, dv = v - v_lead the closing speed, s the gap bumper to bumper; the
interaction term is left out on a free road. The lower bound b_max is the hardest braking (IDM's
own term is unbounded as the gap closes); the gap is floored at GAP_FLOOR_M so that it stays
finite at contact. Metres, seconds, m/s, m/s^2.
"""

from __future__ import annotations

import numpy as np

GAP_FLOOR_M = 1e-3        # gaps below this count as this (the interaction term stays finite)


def idm_desired_gap(speed_mps: float, closing_mps: float, *, min_gap_m: float, headway_s: float,
                    max_accel_mps2: float, comfort_decel_mps2: float) -> float:
    """s* (m): the gap IDM wants at `speed_mps`, closing in on its leader at `closing_mps`
    (own speed minus the leader's). min_gap_m: s0; headway_s: T; max_accel_mps2: a;
    comfort_decel_mps2: b."""
    dynamic = speed_mps * headway_s + speed_mps * closing_mps / (
        2.0 * np.sqrt(max_accel_mps2 * comfort_decel_mps2))
    return min_gap_m + max(0.0, dynamic)


def idm_acceleration(speed_mps: float, desired_speed_mps: float, *, max_accel_mps2: float,
                     max_decel_mps2: float, delta: float = 4, gap_m: float | None = None,
                     desired_gap_m: float = 0.0) -> float:
    """IDM acceleration (m/s^2) at `speed_mps` towards `desired_speed_mps` (v0): free road when
    `gap_m` (bumper to bumper, m) is None, else also the interaction term with the desired gap
    `desired_gap_m` (s*, `idm_desired_gap`). Bounded below by -max_decel_mps2. delta: the
    free-road exponent. The caller chooses the speeds (a clamp of v0 or of a negative speed)."""
    free = (speed_mps / desired_speed_mps) ** delta
    interaction = 0.0 if gap_m is None else (desired_gap_m / max(gap_m, GAP_FLOOR_M)) ** 2
    return max(-max_decel_mps2, max_accel_mps2 * (1.0 - free - interaction))
