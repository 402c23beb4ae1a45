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


# -- the hard brake: a warning with a short time to contact (CONFIG.short_ttc_s = 1.5 s) ----------

def test_short_ttc_brakes_hard_even_below_the_speed_threshold(agent):
    assert CONFIG.short_ttc_s == 1.5
    # 3 m/s is below the speed threshold (5): no mild plan applies, the hard brake does
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False, ttc_s=1.0) == "hard"
    assert agent.braking_frames_left is None          # one frame, no sustained state


def test_long_ttc_below_the_speed_threshold_does_nothing(agent):
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=True, ttc_s=2.5) is None


def test_long_ttc_at_high_speed_keeps_the_milder_plans(agent):
    assert agent.decide(alert=True, speed_mps=25.0, obstacle_ahead=False, ttc_s=2.5) == "single"
    assert agent.decide(alert=True, speed_mps=25.0, obstacle_ahead=True, ttc_s=2.5) == "sustained"


def test_short_ttc_wins_over_the_milder_plans_at_high_speed(agent):
    assert agent.decide(alert=True, speed_mps=25.0, obstacle_ahead=True, ttc_s=0.5) == "hard"
    assert agent.braking_frames_left is None          # the sustained plan did not start


def test_the_short_ttc_bound_is_strict(agent):
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False, ttc_s=1.5) is None
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False, ttc_s=1.49) == "hard"


def test_a_time_to_contact_without_an_alert_does_not_brake(agent):
    assert agent.decide(alert=False, speed_mps=3.0, obstacle_ahead=False, ttc_s=0.5) is None
    assert agent.decide(alert=False, speed_mps=25.0, obstacle_ahead=True, ttc_s=0.5) is None
    assert agent.braking_frames_left is None


def test_the_time_to_contact_is_perceived_for_one_frame_only(agent):
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False, ttc_s=1.0) == "hard"
    # the next frame brings no time to contact: the old ttc(1.0) is gone with the other percepts
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False) is None
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False, ttc_s=2.0) is None


def test_a_hard_brake_interrupts_a_sustained_deceleration_which_then_goes_on(agent):
    assert agent.decide(alert=True, speed_mps=12.0, obstacle_ahead=True) == "sustained"   # N = 8
    assert agent.braking_frames_left == pytest.approx(7.0)
    assert agent.decide(alert=True, speed_mps=11.0, obstacle_ahead=True, ttc_s=0.8) == "hard"
    assert agent.braking_frames_left == pytest.approx(7.0)        # braking(K) survives, not counted down
    assert agent.decide(alert=False, speed_mps=9.0, obstacle_ahead=False) == "sustained"
    assert agent.braking_frames_left == pytest.approx(6.0)


def test_no_hard_brake_once_the_ego_has_stopped(agent):
    assert agent.decide(alert=True, speed_mps=0.3, obstacle_ahead=True, ttc_s=0.2) is None
    assert agent.decide(alert=True, speed_mps=0.5, obstacle_ahead=True, ttc_s=0.2) is None     # V > S strict
    # and a sustained deceleration ends there rather than braking hard
    assert agent.decide(alert=True, speed_mps=12.0, obstacle_ahead=True) == "sustained"
    assert agent.decide(alert=True, speed_mps=0.3, obstacle_ahead=True, ttc_s=0.2) is None
    assert agent.braking_frames_left is None


def test_reset_forgets_the_time_to_contact():
    agent = DecelerationAgent(CONFIG)
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False, ttc_s=1.0) == "hard"
    agent.reset()
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False) is None


def test_short_ttc_is_a_parameter():
    from dataclasses import replace

    agent = DecelerationAgent(replace(CONFIG, short_ttc_s=3.0))
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False, ttc_s=2.5) == "hard"
    agent = DecelerationAgent(replace(CONFIG, short_ttc_s=0.5))
    assert agent.decide(alert=True, speed_mps=3.0, obstacle_ahead=False, ttc_s=1.0) is None


def test_system2_config_comes_from_the_guard_config():
    from riskmap.guard.guarded import GuardConfig, system2_config

    config = system2_config(GuardConfig(decel_mps2=4.0, decision_hz=3, short_ttc_s=2.0))
    assert (config.decel_mps2, config.control_hz, config.short_ttc_s) == (4.0, 3, 2.0)
    default = system2_config(GuardConfig())
    assert default.short_ttc_s == GuardConfig().short_ttc_s == 1.5
