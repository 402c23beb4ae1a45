"""Every plan of deceleration.asl is exercised through the real AgentSpeak interpreter."""

import math

import pytest

pytest.importorskip("agentspeak")

from riskmap.guard.system2 import DecelerationAgent, System2Config

CONFIG = System2Config(speed_threshold_mps=5.0, decel_mps2=3.0, control_hz=2.0, stop_speed_mps=0.5)


@pytest.fixture
def agent():
    return DecelerationAgent(CONFIG)


def test_no_alert_leaves_control_to_the_planner(agent):
    assert agent.decide(alert=False, speed_mps=20.0, obstacle_ahead=True) is None
    assert agent.braking_frames_left is None


def test_alert_below_speed_threshold_does_nothing(agent):
    assert agent.decide(alert=True, speed_mps=4.0, obstacle_ahead=True) is None


def test_algorithm1_single_frame_slowdown(agent):
    # alert ∧ high speed, nothing ahead: one frame, no sustained state left behind
    assert agent.decide(alert=True, speed_mps=12.0, obstacle_ahead=False) == "single"
    assert agent.braking_frames_left is None
    assert agent.decide(alert=False, speed_mps=12.0, obstacle_ahead=False) is None


@pytest.mark.parametrize("speed", [12.0, 13.0, 6.2])
def test_sustained_deceleration_lasts_v0_over_a_times_f_frames(agent, speed):
    expected = math.ceil(speed / CONFIG.decel_mps2 * CONFIG.control_hz)
    decisions = [agent.decide(alert=True, speed_mps=speed, obstacle_ahead=True)]
    # the warning is gone, yet the deceleration goes on for its N frames (speed kept above stop)
    decisions += [agent.decide(alert=False, speed_mps=speed, obstacle_ahead=False) for _ in range(expected + 2)]
    assert decisions[:expected] == ["sustained"] * expected
    assert decisions[expected:] == [None] * 3
    assert agent.braking_frames_left is None


def test_sustained_deceleration_counts_down_its_belief(agent):
    agent.decide(alert=True, speed_mps=12.0, obstacle_ahead=True)      # N = 8, this frame included
    assert agent.braking_frames_left == pytest.approx(7.0)
    agent.decide(alert=False, speed_mps=11.0, obstacle_ahead=False)
    assert agent.braking_frames_left == pytest.approx(6.0)


def test_sustained_deceleration_ends_when_stopped(agent):
    assert agent.decide(alert=True, speed_mps=12.0, obstacle_ahead=True) == "sustained"
    assert agent.decide(alert=False, speed_mps=0.2, obstacle_ahead=True) is None
    assert agent.braking_frames_left is None


def test_reset_drops_a_deceleration_in_progress(agent):
    agent.decide(alert=True, speed_mps=12.0, obstacle_ahead=True)
    agent.reset()
    assert agent.braking_frames_left is None
    assert agent.decide(alert=False, speed_mps=12.0, obstacle_ahead=False) is None


def test_speed_threshold_belief_can_be_replaced(agent):
    agent.set_speed_threshold(15.0)
    assert agent.decide(alert=True, speed_mps=12.0, obstacle_ahead=False) is None
    assert agent.decide(alert=True, speed_mps=16.0, obstacle_ahead=False) == "single"
