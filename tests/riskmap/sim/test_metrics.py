import numpy as np
import pytest

from riskmap.sim.metrics import (
    SafetyConfig,
    ade_m,
    dangerous_encounters,
    goal_error_m,
    mean_jerk_mps3,
    path_length_m,
    safety_pct,
    summarise_metric,
)


def _states(xy: np.ndarray, heading: float, speed: float) -> np.ndarray:
    """[T, 6] states along positions xy [T, 2] with one heading and speed."""
    t = len(xy)
    return np.column_stack([xy, np.full(t, np.cos(heading)), np.full(t, np.sin(heading)),
                            np.full(t, speed), np.zeros(t)])


def test_ade_and_goal_error_against_a_float64_loop():
    rng = np.random.default_rng(0)
    ego = rng.normal(size=(9, 2)) * 10
    human = rng.normal(size=(9, 2)) * 10
    expected = sum(((ego[i, 0] - human[i, 0]) ** 2 + (ego[i, 1] - human[i, 1]) ** 2) ** 0.5
                   for i in range(9)) / 9
    assert ade_m(ego, human) == pytest.approx(expected, rel=1e-12)
    assert goal_error_m(ego, human) == pytest.approx(np.hypot(*(ego[-1] - human[-1])), rel=1e-12)
    assert ade_m(human, human) == 0.0


def test_an_ego_that_stopped_early_stays_where_it_ended():
    human = np.column_stack([np.arange(5.0) * 10, np.zeros(5)])      # 0, 10, ..., 40 m
    ego = human[:2]                                                  # ended at 10 m after 1 step
    assert ade_m(ego, human) == pytest.approx((0 + 0 + 10 + 20 + 30) / 5)
    assert goal_error_m(ego, human) == pytest.approx(30.0)
    assert ade_m(np.vstack([human, [[50.0, 0.0]]]), human) == 0.0     # extra ego steps do not count


def test_path_length_and_jerk_closed_form():
    # x = t^3 / 6 has jerk exactly 1 m/s^3; 3-4-5 steps are 5 m each.
    dt = 0.1
    t = np.arange(50) * dt
    xy = np.column_stack([t ** 3 / 6.0, np.zeros_like(t)])
    assert mean_jerk_mps3(xy, dt) == pytest.approx(1.0, rel=1e-9)
    steps = np.cumsum(np.tile([[3.0, 4.0]], (5, 1)), axis=0)
    assert path_length_m(np.vstack([[0.0, 0.0], steps])) == pytest.approx(25.0)
    assert mean_jerk_mps3(xy[:3], dt) == 0.0


def _encounter(other_xy, other_heading, other_speed, ego_speed=20.0, steps=1):
    ego = _states(np.zeros((steps, 2)), 0.0, ego_speed)
    other = _states(np.tile(other_xy, (steps, 1)), other_heading, other_speed)[None]
    return dangerous_encounters(ego, np.array([5.0, 2.0]), other, np.ones((1, steps), bool),
                                np.array([[5.0, 2.0]]))


def test_dangerous_encounters_hand_built():
    # Same lane, 0.5 m bumper gap, same speed: too close.
    assert _encounter([5.5, 0.0], 0.0, 20.0) == (1, 1)
    # Adjacent lane (4 m between centres: 2 m clearance), overtaking at +10 m/s: not dangerous,
    # the boxes never meet.
    assert _encounter([0.0, 4.0], 0.0, 30.0) == (0, 1)
    # Same lane, 15 m gap, closing at 20 m/s: contact after 0.75 s < 1.5 s.
    assert _encounter([20.0, 0.0], 0.0, 0.0) == (1, 1)
    # Same lane, 15 m gap, closing at 5 m/s: 3 s away.
    assert _encounter([20.0, 0.0], 0.0, 15.0) == (0, 1)
    # Oncoming in the next lane at a combined 40 m/s: passes without contact.
    assert _encounter([20.0, 4.0], np.pi, 20.0) == (0, 1)
    # Beyond the encounter radius: not an encounter at all.
    assert _encounter([40.0, 0.0], 0.0, 0.0) == (0, 0)
    # Counted per step: three steps of the same close vehicle are three encounters.
    assert _encounter([5.5, 0.0], 0.0, 20.0, steps=3) == (3, 3)


def test_invalid_agents_are_no_encounters_and_config_applies():
    ego = _states(np.zeros((2, 2)), 0.0, 0.0)
    other = _states(np.array([[5.5, 0.0], [5.5, 0.0]]), 0.0, 0.0)[None]
    valid = np.array([[True, False]])
    sizes = np.array([[5.0, 2.0]])
    assert dangerous_encounters(ego, sizes[0], other, valid, sizes) == (1, 1)
    lenient = SafetyConfig(close_gap_m=0.25)
    assert dangerous_encounters(ego, sizes[0], other, valid, sizes, lenient) == (0, 1)
    assert safety_pct(1, 4) == 25.0 and safety_pct(0, 0) == 0.0


def test_summarise_metric_matches_numpy():
    values = [3.0, 1.0, None, 7.0, float("nan"), 2.0]
    s = summarise_metric(values)
    assert s["n"] == 4 and s["mean"] == pytest.approx(3.25)
    assert s["p90"] == pytest.approx(np.percentile([3.0, 1.0, 7.0, 2.0], 90))
    assert summarise_metric([None])["mean"] is None
