"""The guard in the closed-loop harness: it slows the ego down, around a planner and around IDM."""

import numpy as np
import pytest

pytest.importorskip("agentspeak")

from riskmap.guard.aggressors import GUARD_AGGRESSION, AggressorHook
from riskmap.guard.guarded import GuardConfig, GuardedHumanDriver, GuardedPlanner, system2_config
from riskmap.guard.system2 import DecelerationAgent, System2Config
from riskmap.planner.baselines import ConstantVelocityPlanner
from riskmap.sim.loop.plan import HumanDriver
from riskmap.sim.loop.rollout import DriveHooks
from riskmap.sim.worlds.episode import make_env

# Alert always on and every speed "high": every decision step is an intervention.
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

ALWAYS = GuardConfig(trigger="always", speed_threshold_mps={"highway": 1.0})
CONFIG = DriveConfig("highway-v0", 1, seed=3, episode_s=3.0)


@pytest.fixture(scope="module")
def env():
    return make_env("highway-v0", 10)


def _agent():
    return DecelerationAgent(System2Config(decel_mps2=ALWAYS.decel_mps2, control_hz=ALWAYS.decision_hz))


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["idm", "cv"])
def test_guard_takes_over_every_frame_and_slows_the_ego(env, kind):
    if kind == "idm":
        alone, guarded = HumanDriver(), GuardedHumanDriver(None, _agent(), ALWAYS)
    else:
        alone, guarded = ConstantVelocityPlanner(), GuardedPlanner(ConstantVelocityPlanner(), None, _agent(), ALWAYS)
    base = drive_episode(env, alone, CONFIG, 0)
    run = drive_episode(env, guarded, CONFIG, 0)
    summary = guarded.guard.summary()
    assert summary["frames"] == 6                       # 3 s at 2 Hz
    assert summary["interventions"] == 6 and summary["intervention_ratio"] == 1.0
    assert {e["mode"] for e in guarded.guard.log} <= {"single", "sustained"}
    # braking at 3 m/s² for 3 s costs at least a few metres against the same traffic alone
    assert run["distance_m"] < base["distance_m"] - 3.0


@pytest.mark.slow
def test_aggressor_hook_installs_a_scripted_neighbour(env):
    hook = AggressorHook()
    drive_episode(env, HumanDriver(), DriveConfig("highway-v0", 1, seed=0, episode_s=1.0), 0, hooks=DriveHooks(on_ready=(hook,)))
    assert hook.aggressor is not None
    # the toolkit's one aggressive driver (riskmap.sim.drivers.aggressive), aimed at the ego
    assert type(hook.aggressor).__name__ == "AggressiveVehicle"
    assert hook.aggressor.TIME_WANTED == hook.params.time_gap_s
    assert hook.aggressor.params == GUARD_AGGRESSION and hook.aggressor.params.pace_ahead_m == 5.0


class UrgentPredictor:
    """System 1 stand-in: every neighbour alerts with a short time to contact."""

    alert_threshold = 0.6

    def score(self, tracks, ego, neighbours, last_step, segment_steps):
        n = len(neighbours)
        return np.full(n, 0.99), np.full(n, 0.5)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["idm", "cv"])
def test_hard_brake_slows_the_ego_harder_than_the_plain_deceleration(env, kind):
    hard = GuardConfig(trigger="tgat")
    if kind == "idm":
        mild = GuardedHumanDriver(None, _agent(), ALWAYS)
        urgent = GuardedHumanDriver(UrgentPredictor(), DecelerationAgent(system2_config(hard)), hard)
    else:
        mild = GuardedPlanner(ConstantVelocityPlanner(), None, _agent(), ALWAYS)
        urgent = GuardedPlanner(ConstantVelocityPlanner(), UrgentPredictor(), DecelerationAgent(system2_config(hard)),
                                hard)
    run_mild = drive_episode(env, mild, CONFIG, 0)
    run_hard = drive_episode(env, urgent, CONFIG, 0)
    summary = urgent.guard.summary()
    assert summary["frames"] == 6 and summary["hard"] == summary["interventions"] == 6
    assert {e["ttc_s"] for e in urgent.guard.log} == {0.5}
    # 8 m/s² against 3 m/s² over 3 s (while it moves): well beyond 5 m less
    assert run_hard["distance_m"] < run_mild["distance_m"] - 5.0
