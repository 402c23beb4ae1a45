"""Parameterised highway scenarios: a base scene plus a bounded parameter vector that alters it.

A template names its parameters (perception degradation of what the ego's planner is shown, and
the initial conditions and manoeuvre of one target vehicle), their bounds and their neutral
values. `Template.scenario(values)` turns one vector into the callbacks of one closed-loop
episode (`riskmap.sim.loop.rollout.DriveHooks`): at the neutral vector the road is exactly the base scene and
the planner sees exactly what was recorded.

Templates (highway-v0, 4 lanes; lane 0 is the leftmost in the driving direction):
    lead_brakes  the target drives ahead in the ego's lane and brakes to a standstill;
    cut_in       the target drives ahead in the lane to the ego's left and changes into the
                 ego's lane, optionally braking as it does.
Only the ego and the target are on the road, so an episode is cheap and its outcome is caused
by the parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adversary.search.perceived_idm import perceiving_idm_class
from rasterize.errors import InputError
from rasterize.frames import world_from_highway_env
from rasterize.scene import HX, HY, SPEED, Scene, X, Y

ENV_ID = "highway-v0"
SCENE_RADIUS_M = 120.0      # the recorder's scene radius: a sensing range this long removes nothing


@dataclass(frozen=True)
class Parameter:
    name: str
    low: float
    high: float
    neutral: float            # the base scene's value
    unit: str

    def __post_init__(self) -> None:
        if not self.low <= self.neutral <= self.high:
            raise InputError(f"parameter {self.name}: neutral {self.neutral} outside "
                             f"[{self.low}, {self.high}]")


PERCEPTION_PARAMETERS = (
    Parameter("position_noise_m", 0.0, 3.0, 0.0, "m"),          # σ of Gaussian noise on x, y
    Parameter("heading_noise_rad", 0.0, 0.5, 0.0, "rad"),       # σ of Gaussian heading noise
    Parameter("drop_probability", 0.0, 0.8, 0.0, "1"),          # per agent and planning call
    Parameter("sensing_range_m", 15.0, SCENE_RADIUS_M, SCENE_RADIUS_M, "m"),
    Parameter("latency_steps", 0.0, 4.0, 0.0, "0.5 s steps"),   # others shown this many steps late
)


@dataclass(frozen=True)
class BaseScene:
    """The fixed part of a template (speeds in m/s, distances in m, accelerations in m/s²)."""

    ego_lane: int = 1
    ego_s_m: float = 100.0              # longitudinal position of the ego on the straight road
    ego_speed_mps: float = 25.0
    ego_brake_mps2: float = 6.0         # the ego's strongest braking (the tracking controller's limit)
    target_lane_offset: int = 0         # target lane = ego lane + this (-1: the lane to the left)
    target_final_speed_fraction: float = 0.0   # braking ends at this share of the target's speed


@dataclass(frozen=True)
class TargetScript:
    """What the target does: keep its speed, then at `manoeuvre_time_s` change into `lane_after`
    (if not None) and brake at `brake_mps2` until it reaches `final_speed_mps`."""

    manoeuvre_time_s: float
    brake_mps2: float
    final_speed_mps: float
    lane_after: tuple | None
    dt_s: float


def scripted_vehicle_class():
    """A highway-env vehicle that follows a `TargetScript` with highway-env's own lane controller."""
    from highway_env.vehicle.controller import ControlledVehicle

    class ScriptedVehicle(ControlledVehicle):
        def __init__(self, road, position, heading, speed, lane_index, script: TargetScript):
            super().__init__(road, position, heading, speed, target_lane_index=lane_index,
                             target_speed=speed)
            self.script, self.elapsed_s = script, 0.0

        def act(self, action=None):
            script = self.script
            self.follow_road()
            started = self.elapsed_s >= script.manoeuvre_time_s - 1e-9
            if started and script.lane_after is not None:
                self.target_lane_index = script.lane_after
            if started and script.brake_mps2 > 0 and self.speed > script.final_speed_mps:
                # Brake at the scripted rate, never below the final speed within one step.
                accel = max(-script.brake_mps2, (script.final_speed_mps - self.speed) / script.dt_s)
            elif started and script.brake_mps2 > 0:
                accel = self.speed_control(script.final_speed_mps)
            else:
                accel = self.speed_control(self.target_speed)
            steering = float(np.clip(self.steering_control(self.target_lane_index),
                                     -self.MAX_STEERING_ANGLE, self.MAX_STEERING_ANGLE))
            super(ControlledVehicle, self).act({"steering": steering, "acceleration": accel})

        def step(self, dt):
            super().step(dt)
            self.elapsed_s += dt

    return ScriptedVehicle


@dataclass(frozen=True)
class Template:
    name: str
    description: str
    initial_parameters: tuple[Parameter, ...]
    base: BaseScene
    lane_change: bool                  # the target changes into the ego's lane at the manoeuvre

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return PERCEPTION_PARAMETERS + self.initial_parameters

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.low for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.high for p in self.parameters])

    @property
    def neutral(self) -> np.ndarray:
        return np.array([p.neutral for p in self.parameters])

    def as_dict(self, values: np.ndarray) -> dict[str, float]:
        values = np.asarray(values, dtype=np.float64)
        if values.shape != (len(self.parameters),):
            raise InputError(f"template {self.name} takes {len(self.parameters)} parameters "
                             f"({', '.join(self.names)}), got shape {values.shape}")
        return {n: float(v) for n, v in zip(self.names, values)}

    def normalised(self, values: np.ndarray) -> np.ndarray:
        """Parameters mapped to [0, 1] by their bounds (the space distances are measured in)."""
        return (np.asarray(values, dtype=np.float64) - self.lower) / (self.upper - self.lower)

    def target_speeds(self, p: dict[str, float]) -> tuple[float, float]:
        """(initial speed, speed after braking) of the target, m/s."""
        v = max(0.0, self.base.ego_speed_mps + p["rel_speed_mps"])
        return v, (v * self.base.target_final_speed_fraction if p["brake_mps2"] > 0 else v)

    def scenario(self, values: np.ndarray, seed: int, dt_s: float) -> Scenario:
        return Scenario(self, self.as_dict(values), seed, dt_s)


def _initial(gap, rel_speed, manoeuvre, brake):
    return (
        Parameter("gap_m", *gap, "m"),                       # bumper-to-bumper, target ahead
        Parameter("rel_speed_mps", *rel_speed, "m/s"),       # target speed − ego speed
        Parameter("lateral_offset_m", -1.5, 1.5, 0.0, "m"),  # target's start off its lane centre, + left
        Parameter("manoeuvre_time_s", *manoeuvre, "s"),
        Parameter("brake_mps2", *brake, "m/s²"),
    )


TEMPLATES: dict[str, Template] = {
    "lead_brakes": Template(
        "lead_brakes", "the vehicle ahead in the ego's lane brakes to a standstill",
        _initial(gap=(10.0, 80.0, 40.0), rel_speed=(-8.0, 5.0, 0.0), manoeuvre=(1.0, 6.0, 3.0),
                 brake=(1.0, 8.0, 3.0)),
        BaseScene(target_lane_offset=0, target_final_speed_fraction=0.0), lane_change=False),
    "cut_in": Template(
        "cut_in", "a vehicle ahead in the left lane cuts into the ego's lane (and may brake)",
        _initial(gap=(0.0, 60.0, 25.0), rel_speed=(-8.0, 5.0, 0.0), manoeuvre=(0.5, 6.0, 3.0),
                 brake=(0.0, 6.0, 0.0)),
        BaseScene(target_lane_offset=-1, target_final_speed_fraction=0.5), lane_change=True),
}


def get_template(name: str) -> Template:
    if name not in TEMPLATES:
        raise InputError(f"unknown template {name!r}; use one of {', '.join(TEMPLATES)}")
    return TEMPLATES[name]


def perception_is_neutral(p: dict[str, float]) -> bool:
    """True when the perception parameters leave what the ego perceives untouched."""
    return (round(p["latency_steps"]) == 0 and p["position_noise_m"] == 0
            and p["heading_noise_rad"] == 0 and p["drop_probability"] == 0
            and p["sensing_range_m"] >= SCENE_RADIUS_M)


class Scenario:
    """One parameter vector of one template, as the callbacks of a closed-loop episode."""

    def __init__(self, template: Template, params: dict[str, float], seed: int, dt_s: float):
        self.template, self.params, self.seed, self.dt_s = template, params, seed, dt_s
        self.target = None             # the target vehicle once the road is set up
        self.env = None                # the base env once the road is set up

    # -- initial conditions -------------------------------------------------------------------
    def setup(self, base_env) -> None:
        """Put the ego and the target on an empty road (the `DriveHooks.setup` callback)."""
        from highway_env.vehicle.behavior import IDMVehicle

        t, p, road = self.template, self.params, base_env.road
        b = t.base
        ego_lane_index = ("0", "1", b.ego_lane)
        ego_lane = road.network.get_lane(ego_lane_index)
        # An IDM/MOBIL ego (the `idm` planner keeps it; others take over from it) that, once
        # perception is degraded, decides on what a degraded sensor reports.
        neutral = perception_is_neutral(p)
        cls = IDMVehicle if neutral else perceiving_idm_class()
        ego = cls(road, ego_lane.position(b.ego_s_m, 0.0), ego_lane.heading_at(b.ego_s_m),
                  b.ego_speed_mps, target_lane_index=ego_lane_index, target_speed=b.ego_speed_mps)
        if not neutral:
            ego.configure_perception(p, self.seed, self.dt_s)
        target_lane_index = ("0", "1", b.ego_lane + b.target_lane_offset)
        target_lane = road.network.get_lane(target_lane_index)
        s = b.ego_s_m + p["gap_m"] + 0.5 * (ego.LENGTH + ego.LENGTH)
        speed, final_speed = t.target_speeds(p)
        script = TargetScript(p["manoeuvre_time_s"], p["brake_mps2"], final_speed,
                              ego_lane_index if t.lane_change else None, self.dt_s)
        # highway-env's lateral coordinate grows to the right: + left is a negative lateral.
        self.target = scripted_vehicle_class()(
            road, target_lane.position(s, -p["lateral_offset_m"]), target_lane.heading_at(s), speed,
            target_lane_index, script)
        road.vehicles = [ego, self.target]
        road.objects = []
        base_env.controlled_vehicles = [ego]
        self.env = base_env

    # -- perception degradation ---------------------------------------------------------------
    def perceive(self, scene: Scene, step: int) -> Scene:
        """The scene the planner is shown at control step `step` (the `DriveHooks.perceive`
        callback). Agents other than the ego are delayed, limited by range, dropped and made
        noisy; at neutral parameters the recorded scene itself is returned.

        The goal the planner is sent to (`scene.route_xy`, the route rule) is capped behind a
        leader; it is recomputed from the degraded agents, so that a leader the ego does not
        perceive does not hold its goal back either."""
        from dataclasses import replace

        p = self.params
        if perception_is_neutral(p):
            return scene
        latency = round(p["latency_steps"])
        states, valid = scene.states.copy(), scene.valid.copy()
        others = np.arange(states.shape[0]) != scene.ego_index
        if latency:
            # Others appear as they were `latency` scene steps ago; earlier than the record: absent.
            states[others, latency:] = scene.states[others, :-latency]
            valid[others, latency:] = scene.valid[others, :-latency]
            valid[others, :latency] = False
        now, ego = scene.current_index, scene.ego_index
        distance = np.linalg.norm(states[:, now, :2] - states[ego, now, :2], axis=1)
        valid[others & (distance > p["sensing_range_m"])] = False
        rng = np.random.default_rng([self.seed, step])
        dropped = rng.random(states.shape[0]) < p["drop_probability"]
        valid[others & dropped] = False
        noise_xy = rng.normal(0.0, 1.0, states.shape[:2] + (2,)) * p["position_noise_m"]
        states[others, :, X] += noise_xy[others, :, 0]
        states[others, :, Y] += noise_xy[others, :, 1]
        noise_heading = rng.normal(0.0, 1.0, states.shape[:2])[others] * p["heading_noise_rad"]
        angle = np.arctan2(states[others, :, HY], states[others, :, HX]) + noise_heading
        states[others, :, HX], states[others, :, HY] = np.cos(angle), np.sin(angle)
        route_xy = scene.route_xy
        if route_xy is not None and self.env is not None:
            route_xy = self._perceived_route(states[:, now], valid[:, now] & others, scene.sizes)
        return replace(scene, states=states, valid=valid, route_xy=route_xy)

    def _perceived_route(self, states_now: np.ndarray, seen: np.ndarray, sizes: np.ndarray):
        """The route rule's goal polyline (world) with the perceived agents as the only traffic.
        states_now [N, 6] world, seen [N] bool, sizes [N, 2]."""
        from types import SimpleNamespace

        from rasterize.highway import RouteRule, route_ahead

        ego = self.env.vehicle
        # world_from_highway_env flips y; the flip is its own inverse.
        perceived = [SimpleNamespace(
            position=world_from_highway_env(states_now[i, :2]),
            velocity=world_from_highway_env(states_now[i, SPEED] * states_now[i, [HX, HY]]),
            LENGTH=float(sizes[i, 0])) for i in np.flatnonzero(seen)]
        view = SimpleNamespace(network=self.env.road.network, vehicles=[ego, *perceived])
        return route_ahead(view, ego, RouteRule())
