import json
from pathlib import Path

import numpy as np
import pytest

from riskmap.guard.guarded import GuardConfig, GuardedPlanner, decelerated_waypoints, obstacle_ahead
from riskmap.planner.baselines import ConstantVelocityPlanner
from riskmap.sim.loop.control import capped_accel
from riskmap.sim.loop.plan import Planner
from riskmap.sim.loop.world import recorded_history
from tests.scenes import state

REPO = Path(__file__).resolve().parents[3]

agentspeak = pytest.importorskip("agentspeak")

from riskmap.guard.system2 import DecelerationAgent, System2Config


def scene_with(ego_speed=12.0, other_xy=(20.0, 0.0), steps=6, more=()):
    """Ego at the origin heading +x; one car at `other_xy` (and one at each of `more`) heading +x,
    standing; 0.5 s history of `steps`."""
    from rasterize.scene import Scene

    t = 0.5 * np.arange(-(steps - 1), 1)
    ego = [state(ego_speed * ti, 0.0, 0.0, ego_speed) for ti in t]
    others = [[state(x, y, 0.0, 0.0) for _ in t] for x, y in [other_xy, *more]]
    n = 1 + len(others)
    return Scene(np.array([ego, *others]), np.ones((n, steps), bool), np.array([[5.0, 2.0]] * n),
                 np.zeros(n), ego_index=0, current_index=steps - 1, dt=0.5)


class FixedPredictor:
    """Stands in for the TGAT: a fixed score and time to contact per neighbour (the same for all,
    or by agent index from a dict); remembers what it was asked."""

    alert_threshold = 0.6

    def __init__(self, score, ttc=5.0):
        self.value, self.ttc, self.calls = score, ttc, []

    def _of(self, value, neighbours):
        return np.array([value[i] if isinstance(value, dict) else value for i in neighbours], dtype=np.float64)

    def score(self, tracks, ego, neighbours, last_step, segment_steps):
        self.calls.append((list(neighbours), last_step, segment_steps))
        return self._of(self.value, neighbours), self._of(self.ttc, neighbours)


def make(score=0.9, trigger="tgat", threshold=5.0, ttc=5.0, **config):
    agent = DecelerationAgent(System2Config(speed_threshold_mps=threshold, decel_mps2=3.0, control_hz=2.0))
    predictor = FixedPredictor(score, ttc)
    return (GuardedPlanner(ConstantVelocityPlanner(), predictor, agent, GuardConfig(trigger=trigger, **config)),
            predictor)


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
    from riskmap.sim.loop.plan import HumanDriver

    guarded_idm = make_planner("guard:idm")
    assert isinstance(guarded_idm, GuardedHumanDriver) and isinstance(guarded_idm, HumanDriver)
    assert guarded_idm.guard.config.trigger == "tgat"
    # the threshold is the shipped sidecar's (chosen on validation frames when it was trained)
    sidecar = json.loads((REPO / "checkpoints" / "guard_tgat.json").read_text())
    assert guarded_idm.guard.predictor.alert_threshold == pytest.approx(sidecar["alert_threshold"])
    assert 0.0 <= guarded_idm.guard.predictor.alert_threshold <= 1.0
    always = make_planner("guard-always:cv")
    assert isinstance(always, GuardedPlanner) and always.guard.predictor is None
    assert always.guard.config.trigger == "always"
    assert isinstance(make_planner("guarded:cv"), GuardedPlanner)


# -- the hard brake: a warning whose predicted time to contact is short ---------------------------

class FakeVehicle:
    """The closed-loop ego: records the (acceleration, steering) commands that reach it, held to
    its world's cap as the real planned vehicle holds them."""

    accel_cap = None

    def __init__(self):
        self.sent = []

    def command(self, accel, steer_ccw):
        self.sent.append((capped_accel(accel, self.accel_cap), steer_ccw))


class FakeRecorder:
    """Hands the guard the scene it should see as its 6-segment history."""

    def __init__(self, scene):
        self.current, self.num_steps = scene, 1

    def scene(self, step, **_):
        return self.current


class FakeRun:
    """A closed-loop world at time 0 (`riskmap.sim.loop.world.World`'s guard methods only) whose
    recording shows the scene given."""

    def __init__(self, scene):
        self.ego, self.time_s, self.setup, self.recorder = FakeVehicle(), 0.0, None, FakeRecorder(scene)

    def cap_ego_accel(self, cap):
        self.ego.accel_cap = cap

    def history(self, history_s, dt_s, radius_m):
        return recorded_history(self.recorder, history_s, dt_s, radius_m)


def attached(planner, scene):
    """`planner` attached to a fake closed-loop run whose recording shows `scene`."""
    run = FakeRun(scene)
    planner.attach(run)
    return run


def test_hard_brake_caps_the_acceleration_at_the_hard_deceleration_for_one_frame():
    planner, _ = make(score=0.9, ttc=0.8)
    scene = scene_with(ego_speed=12.0, other_xy=(20.0, 0.0))
    run = attached(planner, scene)
    vehicle = run.ego
    plan = planner.plan(scene)
    assert planner.guard.log[-1]["mode"] == "hard"
    assert planner.guard.config.hard_decel_mps2 == 8.0
    assert planner.guard.brake_mps2 == 8.0
    # the plan is re-timed to v0 − 8 t along the planner's own path
    cv = ConstantVelocityPlanner().plan(scene).waypoints
    np.testing.assert_allclose(plan.waypoints, decelerated_waypoints(cv, 12.0, 8.0), atol=1e-12)
    assert plan.waypoints[0, 0] == pytest.approx(12 * 0.5 - 0.5 * 8.0 * 0.25)
    # the ego's acceleration is capped at −8 m/s² for this decision frame (0.5 s) …
    vehicle.command(2.0, 0.1)
    vehicle.command(-9.0, 0.0)                      # a harder brake of the planner's own stays
    run.time_s = 0.4
    vehicle.command(0.0, 0.0)
    assert vehicle.sent == [(-8.0, 0.1), (-9.0, 0.0), (-8.0, 0.0)]
    # … and not after it
    run.time_s = 0.5
    vehicle.command(1.5, 0.0)
    assert vehicle.sent[-1] == (1.5, 0.0)


def test_a_milder_decision_after_a_hard_brake_uses_the_milder_deceleration():
    planner, predictor = make(score=0.9, ttc=0.8)
    scene = scene_with(ego_speed=12.0, other_xy=(20.0, 0.0))
    run = attached(planner, scene)
    planner.plan(scene)
    assert planner.guard.log[-1]["mode"] == "hard"
    predictor.ttc = 2.5                                # contact no longer close: the sustained plan
    run.time_s = 0.5
    plan = planner.plan(scene)
    assert planner.guard.log[-1]["mode"] == "sustained" and planner.guard.brake_mps2 == 3.0
    np.testing.assert_allclose(plan.waypoints, decelerated_waypoints(
        ConstantVelocityPlanner().plan(scene).waypoints, 12.0, 3.0), atol=1e-12)
    run.ego.command(2.0, 0.0)
    assert run.ego.sent[-1] == (-3.0, 0.0)


def test_hard_brake_deceleration_is_a_guard_setting():
    planner, _ = make(score=0.9, ttc=0.8, hard_decel_mps2=8.0)
    scene = scene_with(ego_speed=12.0)
    run = attached(planner, scene)
    plan = planner.plan(scene)
    run.ego.command(0.0, 0.0)
    assert run.ego.sent == [(-8.0, 0.0)]
    assert plan.waypoints[0, 0] == pytest.approx(12 * 0.5 - 0.5 * 8.0 * 0.25)


def test_hard_brake_below_the_speed_threshold_and_the_log_and_summary():
    planner, _ = make(score=0.9, ttc=1.0)
    slow = scene_with(ego_speed=3.0, other_xy=(20.0, 6.0))       # below 5 m/s, nothing ahead
    planner.reset(slow)
    planner.plan(slow)
    planner.plan(slow)
    entry = planner.guard.log[-1]
    assert entry["mode"] == "hard" and entry["ttc_s"] == 1.0 and entry["alert"] is True
    assert entry["max_score"] == pytest.approx(0.9)
    summary = planner.guard.summary()
    assert summary["hard"] == 2 and summary["single"] == summary["sustained"] == 0
    assert summary["interventions"] == 2 and summary["frames"] == 2
    # without the short time to contact the slow ego is left alone
    calm, _ = make(score=0.9, ttc=2.5)
    calm.reset(slow)
    calm.plan(slow)
    assert calm.guard.summary()["hard"] == 0 and calm.guard.log == []


def test_the_time_to_contact_is_the_highest_scoring_neighbours():
    # two neighbours: the nearer (agent 1, 20 m ahead) scores lower than agent 2 (10 m aside)
    scene = scene_with(ego_speed=3.0, other_xy=(20.0, 0.0), more=[(0.0, 10.0)])
    planner, predictor = make(score={1: 0.7, 2: 0.95}, ttc={1: 0.5, 2: 2.5})
    planner.reset(scene)
    planner.plan(scene)
    assert sorted(predictor.calls[-1][0]) == [1, 2]
    assert planner.guard.log == []                     # ttc 2.5 s of the top scorer: not urgent
    planner, _ = make(score={1: 0.95, 2: 0.7}, ttc={1: 0.5, 2: 2.5})
    planner.reset(scene)
    planner.plan(scene)
    assert planner.guard.log[-1]["mode"] == "hard" and planner.guard.log[-1]["ttc_s"] == 0.5


class RecordingAgent:
    """System 2 stand-in: records what the guard tells it."""

    def __init__(self, decision=None):
        self.decision, self.calls = decision, []

    def reset(self):
        pass

    def set_speed_threshold(self, speed_mps):
        pass

    def decide(self, alert, speed_mps, obstacle_ahead, ttc_s=None):
        self.calls.append((alert, speed_mps, obstacle_ahead, ttc_s))
        return self.decision


@pytest.mark.parametrize("score, ttc_passed", [(0.9, 0.7), (0.59, None)])
def test_the_guard_passes_a_time_to_contact_only_with_an_alert(score, ttc_passed):
    from riskmap.guard.guarded import Guard

    agent = RecordingAgent()
    guard = Guard(FixedPredictor(score, ttc=0.7), agent, GuardConfig())
    assert guard.step(scene_with(ego_speed=12.0)) is None
    assert agent.calls == [(score >= 0.6, 12.0, True, ttc_passed)]


def test_the_always_trigger_passes_no_time_to_contact():
    from riskmap.guard.guarded import Guard

    agent = RecordingAgent(decision="single")
    guard = Guard(None, agent, GuardConfig(trigger="always"))
    guard.step(scene_with(ego_speed=12.0, other_xy=(20.0, 6.0)))
    assert agent.calls == [(True, 12.0, False, None)]
    assert guard.log[-1]["ttc_s"] is None and guard.log[-1]["max_score"] is None


def _fresh_checkpoint(path, horizon_s=1.0, threshold=0.37):
    import torch

    from riskmap.guard.tgat import TGAT, TGATConfig
    from riskmap.infra.checkpoint import save_checkpoint

    torch.manual_seed(0)
    config = TGATConfig(horizon_s=horizon_s)
    model = TGAT(config)
    save_checkpoint(path, model, {"model": config.to_dict(), "horizon_s": horizon_s, "alert_threshold": threshold,
                                  "alert_threshold_source": "test"}, kind="guard_tgat")
    return model


def test_predictor_loads_the_sidecars_threshold_and_scores_probabilities_and_ttc(tmp_path):
    import torch

    from rasterize.tracks import Tracks
    from riskmap.guard.features import window_features
    from riskmap.guard.predictor import AccidentPredictor

    model = _fresh_checkpoint(tmp_path / "ck", horizon_s=1.0, threshold=0.37)
    predictor = AccidentPredictor.load(tmp_path / "ck")
    assert predictor.alert_threshold == 0.37 and predictor.model.config.horizon_s == 1.0
    scene = scene_with(ego_speed=12.0, other_xy=(20.0, 0.0), more=[(0.0, 10.0)])
    tracks = Tracks(scene.states, scene.valid, scene.sizes, scene.kinds)
    probs, ttc = predictor.score(tracks, 0, [1, 2], 5, 1)
    assert probs.shape == ttc.shape == (2,) and probs.dtype == ttc.dtype == np.float64
    assert ((probs > 0) & (probs < 1)).all() and (ttc >= 0).all()
    parts = [window_features(tracks, 0, i, 5, 1) for i in (1, 2)]
    with torch.no_grad():
        logits, ref_ttc = model.eval()(*(torch.from_numpy(np.stack([p[k] for p in parts])) for k in range(4)))
    np.testing.assert_allclose(probs, 1.0 / (1.0 + np.exp(-logits.double().numpy())), rtol=1e-6)
    np.testing.assert_allclose(ttc, ref_ttc.double().numpy(), rtol=1e-6)
    empty = predictor.score(tracks, 0, [], 5, 1)
    assert len(empty) == 2 and empty[0].shape == empty[1].shape == (0,)


def test_make_guarded_reads_the_threshold_and_wires_the_short_ttc(tmp_path):
    from riskmap.guard.guarded import make_guarded

    _fresh_checkpoint(tmp_path / "ck", threshold=0.42)
    planner = make_guarded("tgat", "cv", checkpoint=str(tmp_path / "ck"))
    assert isinstance(planner, GuardedPlanner)
    assert planner.guard.predictor.alert_threshold == 0.42
    assert planner.guard.agent.config.short_ttc_s == planner.guard.config.short_ttc_s == 1.5
    assert planner.guard.agent.config.decel_mps2 == planner.guard.config.decel_mps2
    assert make_guarded("tgat", "cv", checkpoint=str(tmp_path / "ck"),
                        alert_threshold=0.9).guard.predictor.alert_threshold == 0.9
