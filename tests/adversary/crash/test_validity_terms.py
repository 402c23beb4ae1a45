"""CRASH's validity terms: the kinematic excess is zero inside a car's limits and grows outside
them, and the adversary-other overlap enters the loss only with its weight."""

import math

import pytest
import torch

from adversary.crash.attack import AttackConfig
from adversary.crash.generate import STEP_S, kinematic_excess
from riskmap.sim.records.failures import MAX_BRAKE_MPS2, MAX_YAW_RATE_RADPS


def _track(speeds, headings):
    """[1, 1, F, 4] (x, y, heading, speed) at 2 Hz; positions do not enter the excess."""
    speeds, headings = torch.tensor(speeds, dtype=torch.float64), torch.tensor(headings, dtype=torch.float64)
    zeros = torch.zeros_like(speeds)
    return torch.stack([zeros, zeros, headings, speeds], -1)[None, None]


def test_a_track_within_the_limits_costs_nothing():
    speeds = [20.0 - 3.0 * STEP_S * k for k in range(12)]          # braking at 3 m/s²
    headings = [0.02 * k for k in range(12)]                        # 0.04 rad/s
    assert kinematic_excess(_track(speeds, headings)).item() == 0.0


@pytest.mark.parametrize("over", [1.0, 3.0])
def test_braking_beyond_the_limit_costs_the_squared_excess(over):
    decel = MAX_BRAKE_MPS2 + over
    speeds = [30.0 - decel * STEP_S * k for k in range(3)] + [30.0 - decel * STEP_S * 2] * 9
    excess = kinematic_excess(_track(speeds, [0.0] * 12)).item()
    assert excess == pytest.approx(2 * over ** 2)


def test_turning_faster_than_the_yaw_limit_costs():
    rate = MAX_YAW_RATE_RADPS + 0.5
    headings = [math.remainder(rate * STEP_S * k, 2 * math.pi) for k in range(12)]   # wraps around
    excess = kinematic_excess(_track([0.1] * 12, headings)).item()
    assert excess == pytest.approx(11 * 0.5 ** 2, rel=1e-6)


def test_the_attack_config_turns_the_terms_on_by_default_and_off_for_the_paper():
    on, off = AttackConfig().generation(True), AttackConfig(validity_terms=False).generation(True)
    assert on.adversary_collision_weight > 0 and on.kinematic_weight > 0
    assert off.adversary_collision_weight == 0 and off.kinematic_weight == 0
