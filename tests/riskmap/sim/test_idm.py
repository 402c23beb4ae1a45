"""The one IDM law (riskmap.sim.drivers.idm) and its two users, against the formula written out here.

Reference (Treiber, Hennecke and Helbing 2000), in plain Python floats (IEEE float64):

    s* = s0 + max(0, v T + v (v - v_lead) / (2 sqrt(a b)))
    dv/dt = max(-b_max, a (1 - (v / v0)^delta - (s* / max(s, 0.001))^2))
"""

from __future__ import annotations

import itertools
import math

import pytest

from riskmap.sim.drivers.idm import GAP_FLOOR_M, idm_acceleration, idm_desired_gap
from riskmap.sim.drivers.reactive_traffic import IdmParams
from riskmap.sim.drivers.recorded_idm import IdmMobilParams, idm_accel

SPEEDS = (0.0, 0.1, 1.0, 5.0, 10.0, 17.3, 29.9, 30.0, 36.0)
GAPS = (None, 0.0, 0.0005, 0.5, 2.0, 8.0, 20.0, 55.0, 140.0)
LEAD_SPEEDS = (0.0, 4.0, 10.0, 22.5, 35.0)


def reference_gap(v: float, v_lead: float, s0: float, T: float, a: float, b: float) -> float:
    return float(s0) + max(0.0, float(v) * T + float(v) * (float(v) - float(v_lead)) / (2.0 * math.sqrt(a * b)))


def reference_accel(v: float, v0: float, gap: float | None, s_star: float, a: float, b_max: float,
                    delta: float) -> float:
    free = (float(v) / float(v0)) ** float(delta)
    interaction = 0.0 if gap is None else (float(s_star) / max(float(gap), 0.001)) ** 2
    return max(-float(b_max), float(a) * (1.0 - free - interaction))


def close(x: float, y: float) -> bool:
    return x == pytest.approx(y, rel=1e-13, abs=1e-13)


def test_the_law_is_the_textbook_formula():
    assert GAP_FLOOR_M == 0.001
    s0, T, a, b, b_max = 2.0, 1.5, 1.5, 2.0, 6.0
    for v, gap, v_lead in itertools.product(SPEEDS, GAPS, LEAD_SPEEDS):
        s_star = idm_desired_gap(v, v - v_lead, min_gap_m=s0, headway_s=T, max_accel_mps2=a,
                                 comfort_decel_mps2=b)
        assert close(s_star, reference_gap(v, v_lead, s0, T, a, b))
        for v0, delta in ((30.0, 4), (25.0, 4.0), (12.0, 3.5), (30.0, 1.0)):
            got = idm_acceleration(v, v0, max_accel_mps2=a, max_decel_mps2=b_max, delta=delta, gap_m=gap,
                                   desired_gap_m=s_star)
            assert close(got, reference_accel(v, v0, gap, s_star, a, b_max, delta)), (v, gap, v_lead, v0, delta)
    # A worked value: v = 10, 20 m behind a leader at 8 m/s, v0 = 30:
    # s* = 17 + 10/sqrt(3), a = 1.5 (1 - 1/81 - (s*/20)^2) = -0.46339011173529...
    s_star = idm_desired_gap(10.0, 2.0, min_gap_m=2.0, headway_s=1.5, max_accel_mps2=1.5, comfort_decel_mps2=2.0)
    assert s_star == pytest.approx(17.0 + 10.0 / math.sqrt(3.0), abs=1e-12)
    assert idm_acceleration(10.0, 30.0, max_accel_mps2=1.5, max_decel_mps2=6.0, gap_m=20.0,
                            desired_gap_m=s_star) == pytest.approx(-0.46339011173529, abs=1e-12)
    # Free road at v0: no acceleration; touching a leader: the hardest braking.
    assert idm_acceleration(30.0, 30.0, max_accel_mps2=1.5, max_decel_mps2=6.0) == 0.0
    assert idm_acceleration(10.0, 30.0, max_accel_mps2=1.5, max_decel_mps2=6.0, gap_m=0.0,
                            desired_gap_m=2.0) == -6.0


def test_reactive_traffic_follows_the_law_with_its_own_numbers():
    """IdmParams: exponent 4, desired speed at least min_desired_speed_mps, s* given by the caller."""
    p = IdmParams()
    for v, gap, v_lead in itertools.product(SPEEDS, GAPS, LEAD_SPEEDS):
        s_star = p.desired_gap(v, v - v_lead)
        assert close(s_star, reference_gap(v, v_lead, p.min_gap_m, p.headway_s, p.max_accel_mps2,
                                           p.comfort_decel_mps2))
        for v0 in (0.0, 0.05, 0.1, 8.0, 30.0):
            expected = reference_accel(v, max(v0, p.min_desired_speed_mps), gap, s_star, p.max_accel_mps2,
                                       p.max_decel_mps2, 4)
            assert close(p.accel(v, v0, gap, s_star), expected), (v, gap, v_lead, v0)
    # No leader: s* does not matter.
    assert p.accel(5.0, 10.0, None, math.inf) == p.accel(5.0, 10.0)


def test_recorded_idm_follows_the_law_with_its_own_numbers():
    """idm_accel: params.delta, a negative speed counts as 0 in the free term, v0 not clamped."""
    for p in (IdmMobilParams(), IdmMobilParams(delta=3.0, desired_speed_mps=20.0, headway_s=1.1, min_gap_m=3.0)):
        for v, gap, v_lead in itertools.product(SPEEDS + (-0.5,), GAPS, LEAD_SPEEDS):
            s_star = reference_gap(v, v_lead, p.min_gap_m, p.headway_s, p.max_accel_mps2, p.comfort_decel_mps2)
            expected = reference_accel(max(v, 0.0), p.desired_speed_mps, gap, s_star, p.max_accel_mps2,
                                       p.max_decel_mps2, p.delta)
            got = idm_accel(v, p) if gap is None else idm_accel(v, p, gap, v_lead)
            assert close(got, expected), (p, v, gap, v_lead)


def test_both_users_agree_where_their_numbers_do():
    """Same parameters, non-negative speeds, v0 above the reactive clamp: the same values, bit for bit."""
    mobil = IdmMobilParams(desired_speed_mps=30.0, headway_s=1.0, min_gap_m=2.0, max_accel_mps2=1.5,
                           comfort_decel_mps2=2.0, delta=4.0, max_decel_mps2=6.0)
    reactive = IdmParams(min_gap_m=2.0, headway_s=1.0, max_accel_mps2=1.5, comfort_decel_mps2=2.0,
                         max_decel_mps2=6.0)
    for v, gap, v_lead in itertools.product(SPEEDS, GAPS, LEAD_SPEEDS):
        s_star = reactive.desired_gap(v, v - v_lead)
        assert reactive.accel(v, 30.0, gap, s_star) == (idm_accel(v, mobil) if gap is None
                                                        else idm_accel(v, mobil, gap, v_lead))
