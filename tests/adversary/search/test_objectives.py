"""Constraint math, objectives and diversity on hand-computed cases (float64)."""

import numpy as np
import pytest

from adversary.search.evaluation import constraint_value
from adversary.search.objectives import (
    COLLISION_PENALTY,
    ObjectiveScales,
    braking_distance_m,
    journey_distance_m,
    penalised_objectives,
    required_gap_m,
    scene_alteration,
    total_distance_m,
)
from adversary.search.report import failure_diversity
from adversary.search.scenarios import get_template
from rasterize.errors import InputError


def test_braking_distance_from_v1_squared_equals_v0_squared_plus_2as():
    assert braking_distance_m(25.0, 0.0, 5.0) == pytest.approx(62.5, abs=1e-12)   # 625 / 10
    assert braking_distance_m(20.0, 10.0, 5.0) == pytest.approx(30.0, abs=1e-12)  # (400-100)/10
    assert braking_distance_m(12.0, 12.0, 0.0) == 0.0                            # nothing to shed
    # Check against a fine explicit integration of constant deceleration.
    dt, v, s = 1e-5, 25.0, 0.0
    while v > 0:
        s += v * dt - 0.5 * 6.0 * dt * dt if v > 6.0 * dt else v * v / 12.0
        v -= 6.0 * dt
    assert braking_distance_m(25.0, 0.0, 6.0) == pytest.approx(s, rel=1e-4)
    with pytest.raises(InputError):
        braking_distance_m(10.0, 20.0, 5.0)
    with pytest.raises(InputError):
        braking_distance_m(20.0, 10.0, 0.0)


def test_required_gap_subtracts_what_the_target_covers_while_braking():
    # Ego 25 m/s braking at 6 to 0: 52.083 m; target 20 m/s braking at 8 to 0: 25 m.
    assert required_gap_m(25.0, 6.0, 20.0, 0.0, 8.0) == pytest.approx(625 / 12 - 25.0, abs=1e-12)
    # A static target (the paper's pedestrian): the gap is the ego's whole braking distance.
    assert required_gap_m(25.0, 6.0, 0.0, 0.0, 1.0) == pytest.approx(625 / 12, abs=1e-12)
    # Ego slower than the target's final speed: it never has to brake.
    assert required_gap_m(10.0, 6.0, 20.0, 20.0, 0.0) == 0.0


def test_template_constraint_matches_hand_numbers():
    t = get_template("lead_brakes")
    p = dict(zip(t.names, t.neutral))
    p.update(gap_m=10.0, rel_speed_mps=-5.0, brake_mps2=8.0)
    x = np.array([p[n] for n in t.names])
    # ego 25 m/s at 6 m/s²: 625/12; lead 20 m/s at 8 m/s² to 0: 25 m; gap 10 m.
    assert constraint_value(t, x) == pytest.approx(625 / 12 - 25.0 - 10.0, abs=1e-12)
    assert constraint_value(t, t.neutral) < 0          # the base scene is solvable
    c = get_template("cut_in")
    p = dict(zip(c.names, c.neutral))
    p.update(gap_m=5.0, rel_speed_mps=-5.0, brake_mps2=4.0)
    x = np.array([p[n] for n in c.names])
    # cutter 20 m/s braking at 4 to half its speed (10): (400-100)/8 = 37.5 m covered;
    # ego from 25 to 10 at 6: (625-100)/12 = 43.75 m.
    assert constraint_value(c, x) == pytest.approx(43.75 - 37.5 - 5.0, abs=1e-12)


def test_objectives_on_a_hand_built_case():
    ego = np.array([[0.0, 0.0], [3.0, 4.0], [6.0, 8.0]])
    target = np.array([[10.0, 0.0], [3.0, 10.0], [6.0, 8.0]])
    assert journey_distance_m(ego) == pytest.approx(10.0, abs=1e-12)
    assert total_distance_m(ego, target) == pytest.approx(10.0 + 6.0 + 0.0, abs=1e-12)
    neutral, low, high = np.array([0.0, 5.0]), np.array([0.0, 0.0]), np.array([2.0, 10.0])
    assert scene_alteration(np.array([1.0, 2.0]), neutral, low, high) == pytest.approx(0.5 + 0.3)
    scales = ObjectiveScales(journey_max_m=100.0, steps_max=2, distance_max_m=20.0, n_params=2)
    safe = penalised_objectives(10.0, 16.0, 0.8, False, scales)
    np.testing.assert_allclose(safe, [0.9, 16.0 / 40.0, 0.4], atol=1e-12)
    crash = penalised_objectives(10.0, 16.0, 0.8, True, scales)
    np.testing.assert_allclose(crash, safe - COLLISION_PENALTY, atol=1e-9)
    # Any colliding scene dominates any collision-free one, however poor its raw objectives.
    worst_crash = penalised_objectives(0.0, 1e9, 2.0, True, scales)
    best_safe = penalised_objectives(100.0, 0.0, 0.0, False, scales)
    assert np.all(worst_crash < best_safe)


def test_failure_diversity_is_the_range_of_mean_pairwise_distances():
    t = get_template("lead_brakes")
    span = t.upper - t.lower
    z = np.zeros((3, len(t.names)))
    z[1, 0] = 1.0        # distance 1 from the first
    z[2, 1] = 1.0        # distance 1 from the first, sqrt(2) from the second
    x = t.lower + z * span
    lo, hi = failure_diversity(t, x)
    means = [(1 + 1) / 2, (1 + np.sqrt(2)) / 2, (1 + np.sqrt(2)) / 2]
    assert (lo, hi) == pytest.approx((min(means), max(means)), abs=1e-12)
    assert failure_diversity(t, x[:1]) is None
