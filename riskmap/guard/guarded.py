"""`GuardedPlanner`: the dual-system guard wrapped around any planner (and around the IDM ego).

Every decision step (2 Hz, the segment rate of the accident predictor):
  System 1  scores the two neighbours with the smallest d_s to the ego; the highest score against
            the checkpoint's alert threshold (chosen on validation for a target alert ratio)
            sets the `alert` belief and the predicted time to contact of that neighbour the
            `ttc(T)` belief (trigger "tgat"), or `alert` is simply always present (trigger
            "always": the deceleration plan on at high speed, no time to contact);
  System 2  the AgentSpeak deceleration plans decide, from alert, ttc(T), speed(V) and
            obstacle_ahead, whether this frame is a hard brake ("hard": contact is close), a
            slowdown ("single"), part of a sustained deceleration ("sustained") or left to the
            planner (None).
A slowdown frame lasts one decision step (0.5 s) and asks for a deceleration of `decel_mps2`
(`hard_decel_mps2` for a hard brake): in the closed-loop harness the ego's acceleration is capped
at minus that for the frame; the returned plan is also re-timed to that deceleration along the
planner's own path, so that a harness which only tracks plans sees the same intent. Every
intervention is logged.

Around the IDM/MOBIL ego (SPEC `guard:idm`) there is no plan to wrap: `GuardedHumanDriver`
replaces the ego by an IDM vehicle with the same parameters whose acceleration is capped the same
way whenever System 2 slows it down.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from rasterize.errors import InputError
from rasterize.frames import ego_from_world, ego_pose
from rasterize.geometry import Polyline
from rasterize.scene import Scene
from rasterize.tracks import Tracks
from riskmap.guard.events import nearest_neighbours
from riskmap.guard.features import OBSERVED, SEGMENT_S
from riskmap.registry import make_planner
from riskmap.sim.loop.plan import PLAN_DT_S, HumanDriver, Plan, drives_itself, traits_of

GUARD_CHECKPOINT = "checkpoints/guard_tgat"
LOG = logging.getLogger("riskmap.guard")
TRIGGERS = ("tgat", "always")


@dataclass(frozen=True)
class GuardConfig:
    trigger: str = "tgat"               # "tgat" or "always"
    neighbours: int = 2                 # scored by System 1 each step (smallest d_s first)
    obstacle_ahead_m: float = 30.0      # x_l: obstacle_ahead if a vehicle is this close ahead …
    obstacle_lateral_m: float = 2.5     # … and at most y_l to either side of the ego's axis (m)
    decel_mps2: float = 3.0             # a
    hard_decel_mps2: float = 8.0        # the hard brake: emergency braking, about 0.8 g (short time to contact)
    short_ttc_s: float = 1.5            # a warning with a predicted time to contact below this is urgent
    decision_hz: int = 2                # f
    # "High speed" per scenario family (m/s): above the family's usual cruising speed band.
    speed_threshold_mps: dict = field(default_factory=lambda: {
        "highway": 20.0, "merge": 20.0, "roundabout": 8.0, "intersection": 5.0})
    default_speed_threshold_mps: float = 10.0


def obstacle_ahead(scene: Scene, ahead_m: float, lateral_m: float) -> bool:
    now, ego = scene.current_index, scene.ego_index
    present = np.flatnonzero(scene.valid[:, now])
    others = present[present != ego]
    if not len(others):
        return False
    origin, heading = ego_pose(scene)
    xy = ego_from_world(scene.states[others, now, :2], origin, heading)
    return bool(((xy[:, 0] > 0) & (xy[:, 0] <= ahead_m) & (np.abs(xy[:, 1]) <= lateral_m)).any())


def decelerated_waypoints(waypoints: np.ndarray, speed_mps: float, decel_mps2: float) -> np.ndarray:
    """The plan's path [12, 2] (ego frame) re-timed to v(t) = max(v0 − a·t, 0)."""
    path = Polyline(np.concatenate([[[0.0, 0.0]], np.asarray(waypoints, dtype=np.float64)]))
    t = PLAN_DT_S * np.arange(1, len(waypoints) + 1)
    t_stop = speed_mps / decel_mps2
    arc = np.where(t < t_stop, speed_mps * t - 0.5 * decel_mps2 * t ** 2, 0.5 * speed_mps * t_stop)
    # Past the planned path: continue straight along its last direction.
    seg = path.segments[-1]
    last = seg / max(np.linalg.norm(seg), 1e-9) if path.length > 1e-9 else np.array([1.0, 0.0])
    return path.point_at(arc, beyond=last)


class Guard:
    """The orchestrator: System 1 → alert belief → System 2, once per decision step."""

    def __init__(self, predictor, agent, config: GuardConfig = GuardConfig()):
        if config.trigger not in TRIGGERS:
            raise InputError(f"guard trigger {config.trigger!r} is not one of {TRIGGERS}")
        self.predictor, self.agent, self.config = predictor, agent, config
        self.run = None
        self.reset()

    def reset(self) -> None:
        self.agent.reset()
        self.log: list[dict] = []
        self.frames = 0
        self.timings_s: list[tuple[float, float]] = []   # (System 1, System 2) per step
        self.brake_until_s = -np.inf
        self.brake_mps2 = self.config.decel_mps2

    def attach(self, run) -> None:
        """A new closed-loop episode: keep its recording (for the 6-segment history) and set the
        family's speed threshold."""
        self.reset()
        self.run = run
        self.agent.set_speed_threshold(self.config.speed_threshold_mps.get(
            _family_of(run), self.config.default_speed_threshold_mps))

    def history_scene(self, fallback: Scene | None) -> Scene:
        """The scene now with OBSERVED segments of history (from the recording when attached)."""
        if self.run is None:
            return fallback.past()
        return self.run.history(SEGMENT_S * (OBSERVED - 1), SEGMENT_S, 80.0)

    def step(self, scene: Scene) -> str | None:
        """One decision: returns None, "single", "sustained" or "hard" (and logs interventions)."""
        cfg = self.config
        t0 = time.perf_counter()
        max_score, ttc_s = None, None
        if cfg.trigger == "tgat":
            neighbours = nearest_neighbours(scene, cfg.neighbours)
            scores, ttcs = self.predictor.score(Tracks.of_scene(scene), scene.ego_index, neighbours, scene.current_index, 1)
            max_score = float(scores.max()) if len(scores) else 0.0
            alert = max_score >= self.predictor.alert_threshold
            ttc_s = float(ttcs[np.argmax(scores)]) if alert else None
        else:
            alert = True
        speed = float(scene.ego_state()[4])
        ahead = obstacle_ahead(scene, cfg.obstacle_ahead_m, cfg.obstacle_lateral_m)
        t1 = time.perf_counter()
        decision = self.agent.decide(alert, speed, ahead, ttc_s)
        t2 = time.perf_counter()
        self.timings_s.append((t1 - t0, t2 - t1))
        self.frames += 1
        if decision is not None:
            now = self.run.time_s if self.run is not None else scene.time_s
            self.brake_until_s = now + 1.0 / cfg.decision_hz - 1e-9
            self.brake_mps2 = cfg.hard_decel_mps2 if decision == "hard" else cfg.decel_mps2
            self.log.append({"time_s": round(float(now), 3), "mode": decision, "alert": bool(alert),
                             "max_score": max_score, "ttc_s": ttc_s, "speed_mps": speed,
                             "obstacle_ahead": ahead})
            LOG.info("guard intervention: %s", self.log[-1])
        return decision

    def braking_now(self) -> bool:
        return self.run is not None and self.run.time_s < self.brake_until_s

    def accel_cap(self) -> float | None:
        """The most acceleration the ego may have now (m/s²): minus the frame's deceleration
        during a slowdown frame, None (no cap) otherwise (`World.cap_ego_accel`)."""
        return -self.brake_mps2 if self.braking_now() else None

    def summary(self) -> dict:
        t = np.array(self.timings_s) if self.timings_s else np.zeros((0, 2))
        return {"frames": self.frames, "interventions": len(self.log),
                "intervention_ratio": len(self.log) / self.frames if self.frames else 0.0,
                "single": sum(e["mode"] == "single" for e in self.log),
                "sustained": sum(e["mode"] == "sustained" for e in self.log),
                "hard": sum(e["mode"] == "hard" for e in self.log),
                "system1_ms": (1000 * t[:, 0]).tolist(), "system2_ms": (1000 * t[:, 1]).tolist()}


def _family_of(run) -> str:
    from riskmap.sim.worlds.episode import FAMILY_SETUPS

    # A recorded world (CommonRoad) has no highway-env family setup: the default threshold applies.
    return next((name for name, setup in FAMILY_SETUPS.items() if setup is getattr(run, "setup", None)), "")


class GuardedPlanner:
    """`Planner` around `planner` with System 1 `predictor` (None for trigger "always") and System 2
    `agent` (a `riskmap.guard.system2.DecelerationAgent`)."""

    def __init__(self, planner, predictor, agent, config: GuardConfig = GuardConfig()):
        self.planner = planner
        self.guard = Guard(predictor, agent, config)
        self.raster = traits_of(planner).raster   # for the drive harness's plan figures

    def reset(self, scene: Scene) -> None:
        self.planner.reset(scene)
        self.guard.reset()

    def attach(self, run) -> None:
        """Closed-loop hook: cap the ego's acceleration during slowdown frames."""
        self.guard.attach(run)
        run.cap_ego_accel(self.guard.accel_cap)

    def plan(self, scene: Scene) -> Plan:
        plan = self.planner.plan(scene)
        t0 = time.perf_counter()
        decision = self.guard.step(self.guard.history_scene(scene))
        plan.timings_s["guard"] = time.perf_counter() - t0
        if decision is not None:
            plan.waypoints = decelerated_waypoints(plan.waypoints, float(scene.ego_state()[4]),
                                                   self.guard.brake_mps2)
        return plan


def guarded_idm_class():
    from highway_env.vehicle.behavior import IDMVehicle

    class GuardedIDMVehicle(IDMVehicle):
        """The IDM/MOBIL ego, with its acceleration capped at −a while System 2 slows it down."""

        def __deepcopy__(self, memo):
            """A copy (a road's twin that predicts where traffic goes, e.g. the scripted
            aggressor's choice of target) drives as the plain IDM vehicle: the guard belongs to
            the episode, and a twin must not add decisions to its log."""
            import copy

            twin = IDMVehicle.__new__(IDMVehicle)
            memo[id(self)] = twin
            for name, value in vars(self).items():
                if name not in ("guard", "_acts"):
                    setattr(twin, name, copy.deepcopy(value, memo))
            return twin

        def act(self, action=None):
            if self.crashed:
                return
            every = max(round(self.guard.run.rate_hz / self.guard.config.decision_hz), 1)
            if self._acts % every == 0:
                self.guard.step(self.guard.history_scene(None))
            self._acts += 1
            super().act()
            if self.guard.braking_now():
                self.action["acceleration"] = min(self.action["acceleration"], -self.guard.brake_mps2)

    return GuardedIDMVehicle


class GuardedHumanDriver(HumanDriver):
    """SPEC `guard:idm`: the simulator's IDM/MOBIL ego, guarded (see the module docstring)."""

    name = "guard:idm"

    def __init__(self, predictor, agent, config: GuardConfig = GuardConfig()):
        self.guard = Guard(predictor, agent, config)

    def attach(self, run) -> None:
        self.guard.attach(run)
        old = run.ego
        new = guarded_idm_class().create_from(old)
        for name in ("TIME_WANTED", "POLITENESS", "DELTA"):   # the sampled driver's parameters
            if name in vars(old):
                setattr(new, name, vars(old)[name])
        new.guard, new._acts = self.guard, 0
        run.replace_ego(new)


def system2_config(config: GuardConfig):
    """System 2's parameters from the guard's (one source for a, f and the short time to contact)."""
    from riskmap.guard.system2 import System2Config

    return System2Config(decel_mps2=config.decel_mps2, control_hz=config.decision_hz,
                         short_ttc_s=config.short_ttc_s)


def make_guarded(trigger: str, inner_spec: str, seed: int = 0, checkpoint: str = GUARD_CHECKPOINT,
                 alert_threshold: float | None = None):
    """A guarded planner (or guarded IDM ego) around `inner_spec`; `alert_threshold` overrides the
    checkpoint's (chosen on validation, see its sidecar)."""
    from riskmap.guard.system2 import DecelerationAgent
    config = GuardConfig(trigger=trigger)
    predictor = None
    if trigger == "tgat":
        from riskmap.guard.predictor import AccidentPredictor

        predictor = AccidentPredictor.load(checkpoint)
        if alert_threshold is not None:
            predictor.alert_threshold = float(alert_threshold)
    agent = DecelerationAgent(system2_config(config))
    inner = make_planner(inner_spec, seed=seed)
    if drives_itself(inner):
        return GuardedHumanDriver(predictor, agent, config)
    return GuardedPlanner(inner, predictor, agent, config)


def tgat_guarded(inner_spec: str, seed: int = 0, **_):
    """Planner SPEC `guard:SPEC` (and `guarded:SPEC`): SPEC behind the TGAT-triggered guard."""
    return make_guarded("tgat", inner_spec, seed=seed)


def always_guarded(inner_spec: str, seed: int = 0, **_):
    """Planner SPEC `guard-always:SPEC`: SPEC with the deceleration plan always on at high speed."""
    return make_guarded("always", inner_spec, seed=seed)
