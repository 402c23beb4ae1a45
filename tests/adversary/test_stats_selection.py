from types import SimpleNamespace

import numpy as np
import pytest

from adversary.attacks.monitor import collision_type
from rasterize.tracks import Tracks
from riskmap.infra.stats import bootstrap_mean, sign_test, wilson
from riskmap.sim.drivers.aggressive import softmin_agent_weights
from riskmap.sim.records.alternatives import ego_only_solution


def test_wilson_interval_matches_the_closed_form():
    k, n, z = 3, 10, 1.959963984540054
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    stat = wilson(k, n)
    assert stat["value"] == pytest.approx(0.3)
    assert stat["lo"] == pytest.approx(centre - half, abs=1e-9)
    assert stat["hi"] == pytest.approx(centre + half, abs=1e-9)
    assert wilson(0, 0) is None


def test_sign_test_matches_the_binomial_by_hand():
    assert sign_test(8, 0) == pytest.approx(2 * 0.5 ** 8)             # all 8 discordant pairs one way
    assert sign_test(0, 8) == sign_test(8, 0)
    # 1 against 3: P(X <= 1) + P(X >= 3) for X ~ Bin(4, 1/2) = (1 + 4 + 4 + 1) / 16
    assert sign_test(1, 3) == pytest.approx(10 / 16)
    assert sign_test(0, 0) == 1.0


def test_bootstrap_is_deterministic_and_brackets_the_mean():
    x = [1.0, 2.0, 3.0, 4.0, 10.0]
    a, b = bootstrap_mean(x), bootstrap_mean(x)
    assert a == b
    assert a["value"] == pytest.approx(4.0)
    assert a["lo"] < a["value"] < a["hi"]
    assert bootstrap_mean([5.0])["lo"] == bootstrap_mean([5.0])["hi"] == 5.0
    assert bootstrap_mean([None]) is None


def test_softmin_weights_against_a_float64_reference():
    d = np.array([[4.0, 2.0], [1.0, 3.0], [0.5, 0.5]])
    eligible = np.array([True, True, False])      # agent 2 is behind the ego: excluded
    tau = 2.0
    pair = np.exp(-d[:2] / tau)
    expected = np.concatenate([pair.sum(1) / pair.sum(), [0.0]])
    w = softmin_agent_weights(d, eligible, tau)
    np.testing.assert_allclose(w, expected, rtol=1e-12)
    assert w.sum() == pytest.approx(1.0)
    assert np.argmax(w) == 1
    assert not softmin_agent_weights(d, np.zeros(3, bool), tau).any()


def _vehicle(x, y, heading_deg, width=2.0):
    return SimpleNamespace(position=np.array([x, y]), heading=np.radians(heading_deg), WIDTH=width)


@pytest.mark.parametrize("partner, expected", [
    (_vehicle(5, 0, 0), "ego rear-ends"),
    (_vehicle(-5, 0.5, 10), "ego rear-ended"),
    (_vehicle(1, 2.5, 5), "sideswipe"),
    (_vehicle(3, 2, 90), "side (angle)"),
    (_vehicle(4, 0, 175), "head-on"),
])
def test_collision_types(partner, expected):
    assert collision_type(_vehicle(0, 0, 0), partner) == expected


def _straight_record(other_x: np.ndarray, other_y: float = 0.0):
    """Ego at 10 m/s along y = 0 from x = 0; one other agent at (other_x[t], other_y); dt 0.1 s."""
    steps = len(other_x)
    states = np.zeros((2, steps, 6))
    states[0, :, 0] = 10.0 * 0.1 * np.arange(steps)
    states[0, :, 2] = 1.0
    states[0, :, 4] = 10.0
    states[1, :, 0] = other_x
    states[1, :, 1] = other_y
    states[1, :, 2] = 1.0
    return Tracks(states, np.ones((2, steps), bool), np.array([[5.0, 2.0], [5.0, 2.0]]), np.zeros(2, np.int8))


def test_braking_solves_a_stopped_car_ahead():
    # A stopped car at x = 35: the ego reaches it after ~3 s at 10 m/s; braking from 3 s earlier
    # (start at x = 0 at 10 m/s, -4 m/s² stops within 12.5 m) avoids it.
    tracks = _straight_record(np.full(31, 35.0))
    assert ego_only_solution(tracks, ego=0, collision_step=30, dt_s=0.1)


def test_no_solution_when_the_other_car_sits_on_the_ego():
    # The other car is on top of the ego's start position the whole time: nothing along the path helps.
    tracks = _straight_record(np.zeros(31))
    assert not ego_only_solution(tracks, ego=0, collision_step=30, dt_s=0.1)
