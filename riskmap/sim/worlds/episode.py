"""One seeded highway-env episode with the IDM/MOBIL "human" ego, stepped at a fixed rate.

Shared by demonstration collection and closed-loop driving, so that a planner driven on seed S
meets exactly the traffic that the human met on seed S.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rasterize.config import family_of_env
from rasterize.scene import Scene
from rasterize.timebase import CONTROL_HZ
from riskmap.sim.worlds import fast_road
from riskmap.sim.loop.control import hand_over_to_planner
from riskmap.sim.records.metrics import centre_off_lane, min_box_gap, vehicle_box
from riskmap.sim.loop.world import recorded_history


@dataclass(frozen=True)
class DriverRanges:
    """Per-episode IDM/MOBIL parameters of the ego, drawn uniformly from these ranges."""

    desired_speed_mps: tuple[float, float]
    time_gap_s: tuple[float, float] = (1.0, 2.0)
    politeness: tuple[float, float] = (0.0, 0.5)


@dataclass(frozen=True)
class FamilySetup:
    """How one scenario family is simulated."""

    episode_s: float                   # simulated seconds per episode
    drivers: DriverRanges
    env_config: dict = field(default_factory=dict)
    keep_radius_m: float = 250.0       # vehicles farther from the ego are removed
    ego_destinations: tuple[str, ...] = ()   # exits the ego may be routed to (random per episode)
    spawn_every_s: float = 0.0         # >0: call the env's own traffic spawner this often
    teacher: str = "idm"               # the demonstrator `riskmap collect` records (a SPEC)


FAMILY_SETUPS: dict[str, FamilySetup] = {
    "highway": FamilySetup(40.0, DriverRanges((20.0, 32.0)), {"vehicles_count": 40}),
    "merge": FamilySetup(25.0, DriverRanges((20.0, 30.0))),
    "roundabout": FamilySetup(20.0, DriverRanges((8.0, 16.0)), {"duration": 20},
                              ego_destinations=("exr", "sxr", "nxr")),
    "intersection": FamilySetup(16.0, DriverRanges((6.0, 10.0)), {"duration": 16},
                                keep_radius_m=150.0, ego_destinations=("o1", "o2", "o3"),
                                spawn_every_s=1.0, teacher="yielding"),
}


def episode_seed(seed: int, episode: int) -> int:
    """Independent, reproducible seed of one episode."""
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def make_env(env_id: str, record_hz: int = CONTROL_HZ, fast: bool | None = None):
    """The gymnasium env of `env_id`, simulated at `record_hz`, with its roads upgraded to
    `riskmap.sim.worlds.fast_road`'s (same physics, less time) unless `fast` is False; `fast=None`
    follows the environment variable RISKMAP_FAST_ROAD (on unless set to 0)."""
    import warnings

    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the envs)

    # The -v0 ids are the ones this toolkit is built and benchmarked on; silence gymnasium's
    # notice that newer versions exist.
    warnings.filterwarnings("ignore", message=".*is out of date.*", category=DeprecationWarning)

    setup = FAMILY_SETUPS[family_of_env(env_id)]
    env_config = {"simulation_frequency": record_hz, "policy_frequency": 1,
                  "duration": setup.episode_s}
    env_config.update(setup.env_config)
    env = gym.make(env_id, config=env_config)
    if fast_road.fast_by_default() if fast is None else fast:
        fast_road.install(env.unwrapped)
    return env


_ENVS: dict = {}


def cached_env(env_id: str, record_hz: int = CONTROL_HZ, fast: bool | None = None):
    """`make_env(env_id, record_hz, fast)`, made once per process: every episode resets it from
    its own seed, so reuse does not change results."""
    key = (env_id, record_hz, fast_road.fast_by_default() if fast is None else bool(fast))
    if key not in _ENVS:
        _ENVS[key] = make_env(env_id, record_hz, key[2])
    return _ENVS[key]


def _install_human_ego(base, rng: np.random.Generator, setup: FamilySetup) -> dict:
    """Replace the env's controlled vehicle by an IDM/MOBIL driver with sampled parameters."""
    from highway_env.vehicle.behavior import IDMVehicle

    old = base.vehicle
    ego = IDMVehicle.create_from(old)
    drivers = setup.drivers
    params = {
        "desired_speed_mps": float(rng.uniform(*drivers.desired_speed_mps)),
        "time_gap_s": float(rng.uniform(*drivers.time_gap_s)),
        "politeness": float(rng.uniform(*drivers.politeness)),
    }
    ego.target_speed = params["desired_speed_mps"]
    ego.TIME_WANTED = params["time_gap_s"]  # instance attributes shadow the class defaults
    ego.POLITENESS = params["politeness"]
    if setup.ego_destinations:
        destination = str(rng.choice(setup.ego_destinations))
        ego.plan_route_to(destination)
        params["destination"] = destination
    base.road.vehicles[base.road.vehicles.index(old)] = ego
    base.controlled_vehicles[0] = ego
    return params


def min_gap_on_road(road, ego, radius_m: float) -> float:
    """Smallest box gap from `ego` to the other vehicles on `road` within `radius_m`."""
    if fast_road.is_fast(road):
        return fast_road.min_gap_on_road(road, ego, radius_m)
    return min_box_gap(vehicle_box(ego), (vehicle_box(v) for v in road.vehicles
                                          if v is not ego and np.linalg.norm(v.position - ego.position) < radius_m))


_CLASS_DEFAULTS: dict = {}


def restore_vehicle_class_defaults() -> None:
    """Undo class-level parameter changes that one env leaves behind for the next.

    highway-env's intersection env sets IDMVehicle.DISTANCE_WANTED / COMFORT_ACC_* on the class
    itself (even when it is only created), so without this a highway episode run after an
    intersection one in the same process would drive with other IDM parameters, and results
    would depend on what ran before. The intersection env sets its values again at each reset.
    The pristine values come from a fresh execution of highway-env's behaviour module, so they
    are right even if an env already changed the live classes.
    """
    import importlib.util

    from highway_env.vehicle import behavior

    if not _CLASS_DEFAULTS:
        spec = importlib.util.spec_from_file_location("_pristine_highway_env_behavior", behavior.__file__)
        fresh = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(fresh)
        for name in ("IDMVehicle", "LinearVehicle"):
            _CLASS_DEFAULTS[getattr(behavior, name)] = {
                k: v for k, v in vars(getattr(fresh, name)).items()
                if k.isupper() and isinstance(v, (int, float))}
    for cls, values in _CLASS_DEFAULTS.items():
        for key in [k for k, v in vars(cls).items() if k.isupper() and isinstance(v, (int, float))
                    and k not in values]:
            delattr(cls, key)
        for key, value in values.items():
            setattr(cls, key, value)


class Episode:
    """Reset `env` for (seed, episode), install the human ego, record every vehicle each step.

    `step()` advances the road by 1 / rate_hz seconds: every vehicle acts (the ego too, whatever
    vehicle drives it), then once a second vehicles far from the ego are dropped and, where the
    family has a spawner, new traffic arrives. `done` once the ego crashed or left the network.
    A `riskmap.sim.loop.world.World`: the planner's scenes come from the recorder.
    """

    def __init__(self, env, env_id: str, seed: int, episode: int, rate_hz: int = CONTROL_HZ,
                 setup=None, static_agents: int = 0):
        """`setup(base_env)`, if given, rearranges the road after the human ego is installed and
        before anything is recorded (scenario templates set their initial conditions there).
        `static_agents`: parked / stopped vehicles added after that
        (`riskmap.sim.drivers.static_agents`), placed by a generator of (seed, episode) alone, so that a
        re-simulation of the episode puts them at the same places."""
        from rasterize.highway import TrafficRecorder

        self.env, self.base = env, env.unwrapped
        self.env_id = env_id
        self.setup = FAMILY_SETUPS[family_of_env(env_id)]
        self.seed = episode_seed(seed, episode)
        restore_vehicle_class_defaults()
        env.reset(seed=self.seed)
        rng = np.random.default_rng([seed, episode, 1])
        self.driver = _install_human_ego(self.base, rng, self.setup)
        if setup is not None:
            setup(self.base)
        self.static_agents = static_agents
        if static_agents:
            from riskmap.sim.drivers.static_agents import place_static_vehicles

            place_static_vehicles(self.base.road, self.ego, family_of_env(env_id), static_agents,
                                  np.random.default_rng([seed, episode, 2]))
        self.rate_hz, self.dt = rate_hz, 1.0 / rate_hz
        self.recorder = TrafficRecorder(self.base.road, self.ego, self.dt)
        self.recorder.record()
        self.steps = 0
        self.crashed = self.off_network = False

    @property
    def ego(self):
        return self.base.vehicle

    @property
    def time_s(self) -> float:
        return self.steps * self.dt

    @property
    def done(self) -> bool:
        return self.crashed or self.off_network

    def hand_over(self, history_s: float) -> tuple[object, Scene]:
        """The ego becomes a `PlannedVehicle` at its state; the planner is reset with the scene
        of the first recorded step."""
        vehicle = hand_over_to_planner(self)
        return vehicle, self.recorder.scene(0, history_s, 0.0)

    def scene(self, history_s: float) -> Scene:
        return self.recorder.scene(self.recorder.num_steps - 1, history_s, 0.0, source=self.env_id)

    def ego_state(self) -> np.ndarray:
        return self.recorder.latest_state(self.recorder.ego_id)

    def min_gap(self, radius_m: float) -> float:
        return min_gap_on_road(self.base.road, self.ego, radius_m)

    def cap_ego_accel(self, cap) -> None:
        self.ego.accel_cap = cap      # the vehicle the planner commands applies it (a replayed one ignores commands)

    def history(self, history_s: float, dt_s: float, radius_m: float) -> Scene:
        return recorded_history(self.recorder, history_s, dt_s, radius_m)

    def replace_ego(self, vehicle) -> None:
        """Hand the ego over to another vehicle object at the same state (same recorded agent)."""
        old = self.ego
        road = self.base.road
        road.vehicles[road.vehicles.index(old)] = vehicle
        self.base.controlled_vehicles[0] = vehicle
        self.recorder.adopt(vehicle, old)

    def step(self) -> None:
        road, ego = self.base.road, self.ego
        road.act()
        road.step(self.dt)
        self.steps += 1
        self.recorder.record()
        if ego.crashed:
            self.crashed = True
            return
        if self.steps % self.rate_hz == 0:
            if centre_off_lane(road, ego):
                self.off_network = True
                return
            road.vehicles = [v for v in road.vehicles if v is ego or
                             np.linalg.norm(v.position - ego.position) <= self.setup.keep_radius_m]
            every = int(round(self.setup.spawn_every_s * self.rate_hz))
            if every and self.steps % every == 0:
                self.base._clear_vehicles()
                self.base._spawn_vehicle(spawn_probability=self.base.config["spawn_probability"])
