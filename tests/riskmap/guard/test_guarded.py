import numpy as np
import pytest

from riskmap.guard.guarded import GuardConfig, GuardedPlanner, decelerated_waypoints, obstacle_ahead
from riskmap.planner.baselines import ConstantVelocityPlanner
from riskmap.sim.plan import Planner
from tests.scenes import state

agentspeak = pytest.importorskip("agentspeak")

from riskmap.guard.system2 import DecelerationAgent, System2Config


def scene_with(ego_speed=12.0, other_xy=(20.0, 0.0), steps=6):
    """Ego at the origin heading +x; one car at `other_xy` heading +x; 0.5 s history of `steps`."""
    from rasterize.scene import Scene

    t = 0.5 * np.arange(-(steps - 1), 1)
    ego = [state(ego_speed * ti, 0.0, 0.0, ego_speed) for ti in t]
    other = [state(other_xy[0], other_xy[1], 0.0, 0.0) for _ in t]
    return Scene(np.array([ego, other]), np.ones((2, steps), bool), np.array([[5.0, 2.0]] * 2),
                 np.zeros(2), ego_index=0, current_index=steps - 1, dt=0.5)


class FixedPredictor:
    """Stands in for the TGAT: a fixed score per neighbour; remembers what it was asked."""

    alert_threshold = 0.6

    def __init__(self, score):
        self.value, self.calls = score, []

    def score(self, states, valid, sizes, kinds, ego, neighbours, last_step, segment_steps):
        self.calls.append((list(neighbours), last_step, segment_steps))
        return np.full(len(neighbours), self.value)


def make(score=0.9, trigger="tgat", threshold=5.0):
    agent = DecelerationAgent(System2Config(speed_threshold_mps=threshold, decel_mps2=3.0, control_hz=2.0))
    predictor = FixedPredictor(score)
    return GuardedPlanner(ConstantVelocityPlanner(), predictor, agent, GuardConfig(trigger=trigger)), predictor


def test_decelerated_waypoints_follow_v0_minus_a_t_along_the_path():
    straight = np.stack([5.0 * np.arange(1, 13), np.zeros(12)], 1)      # 10 m/s plan
    out = decelerated_waypoints(straight, 10.0, 3.0)
    t = 0.5 * np.arange(1, 13)
    t_stop = 10.0 / 3.0
    expected = np.where(t < t_stop, 10.0 * t - 1.5 * t ** 2, 0.5 * 10.0 * t_stop)
    np.testing.assert_allclose(out[:, 0], expected, atol=1e-9)
    np.testing.assert_allclose(out[:, 1], 0.0, atol=1e-12)
    # on a bent path the points stay on the path (here: the L's second leg)
    bent = np.array([[2.5 * k, 0.0] for k in range(1, 5)] + [[10.0, 2.5 * k] for k in range(1, 9)])
    out = decelerated_waypoints(bent, 5.0, 1.0)
    on_path = (np.isclose(out[:, 1], 0.0) & (out[:, 0] <= 10.0 + 1e-9)) | np.isclose(out[:, 0], 10.0)
    assert on_path.all()


def test_obstacle_ahead_region():
    assert obstacle_ahead(scene_with(other_xy=(20.0, 1.0)), 30.0, 2.5)
    assert not obstacle_ahead(scene_with(other_xy=(20.0, 4.0)), 30.0, 2.5)     # next lane
    assert not obstacle_ahead(scene_with(other_xy=(-10.0, 0.0)), 30.0, 2.5)    # behind
    assert not obstacle_ahead(scene_with(other_xy=(40.0, 0.0)), 30.0, 2.5)     # too far


def test_guarded_planner_is_a_planner_and_slows_down_on_alert(caplog):
    planner, predictor = make(score=0.9)
    scene = scene_with(other_xy=(20.0, 0.0))
    assert isinstance(planner, Planner)
    planner.reset(scene)
    with caplog.at_level("INFO", logger="riskmap.guard"):
        plan = planner.plan(scene)
    assert "guard intervention" in caplog.text and "sustained" in caplog.text
    # obstacle ahead, alert, 12 m/s > 5: the sustained plan; waypoints re-timed to 12 − 3t
    assert planner.guard.log[-1]["mode"] == "sustained"
    assert plan.waypoints[0, 0] == pytest.approx(12 * 0.5 - 1.5 * 0.25)
    # System 1 scored the neighbour on the 6-segment window ending now, one segment per step
    assert predictor.calls[-1] == ([1], 5, 1)
    assert planner.guard.summary()["intervention_ratio"] == 1.0


def test_below_alert_threshold_the_planner_keeps_control():
    planner, _ = make(score=0.5)
    scene = scene_with(other_xy=(20.0, 0.0))
    planner.reset(scene)
    plan = planner.plan(scene)
    np.testing.assert_allclose(plan.waypoints, ConstantVelocityPlanner().plan(scene).waypoints)
    summary = planner.guard.summary()
    assert summary["frames"] == 1 and summary["interventions"] == 0 and summary["intervention_ratio"] == 0.0


def test_always_trigger_needs_no_predictor_and_uses_the_single_frame_plan():
    agent = DecelerationAgent(System2Config(speed_threshold_mps=5.0))
    planner = GuardedPlanner(ConstantVelocityPlanner(), None, agent, GuardConfig(trigger="always"))
    scene = scene_with(other_xy=(20.0, 6.0))          # nothing straight ahead
    planner.reset(scene)
    planner.plan(scene)
    assert [e["mode"] for e in planner.guard.log] == ["single"]
    slow = scene_with(ego_speed=3.0, other_xy=(20.0, 6.0))
    planner.plan(slow)
    assert len(planner.guard.log) == 1                 # below the speed threshold: no intervention


def test_unknown_trigger_is_an_input_error():
    from rasterize.errors import InputError

    with pytest.raises(InputError):
        GuardedPlanner(ConstantVelocityPlanner(), None, DecelerationAgent(), GuardConfig(trigger="never"))


def test_registry_builds_guarded_specs_with_the_shipped_checkpoint():
    from riskmap.guard.guarded import GuardedHumanDriver
    from riskmap.registry import make_planner
    from riskmap.sim.plan import HumanDriver

    guarded_idm = make_planner("guard:idm")
    assert isinstance(guarded_idm, GuardedHumanDriver) and isinstance(guarded_idm, HumanDriver)
    assert guarded_idm.guard.config.trigger == "tgat"
    assert guarded_idm.guard.predictor.alert_threshold == pytest.approx(0.6)
    always = make_planner("guard-always:cv")
    assert isinstance(always, GuardedPlanner) and always.guard.predictor is None
    assert always.guard.config.trigger == "always"
    assert isinstance(make_planner("guarded:cv"), GuardedPlanner)
