"""Data-driven closed loop: traffic that replays a recorded human episode with synchronised time.

`record_human_episode` drives the IDM/MOBIL "human" ego on (env, seed, episode) and keeps every
vehicle's recorded states (`HumanLog`). `LogReplayEpisode` then resets the same episode and
replaces every other vehicle by a `ReplayVehicle` that takes its recorded state at each step,
whatever the ego does (the planner paper's evaluation: ado vehicles move as recorded). Vehicles
appear and leave as they did in the record; the episode ends where the record ends.
`ReplayPlanner` (SPEC `replay`) is log playback of the human ego itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rasterize.config import family_of_env
from rasterize.errors import InputError
from rasterize.frames import ego_from_world, heading_angle, highway_env_from_world, world_from_highway_env
from rasterize.scene import Scene
from rasterize.timebase import CONTROL_HZ
from rasterize.tracks import Tracks
from riskmap.infra.atomic import write_npz
from riskmap.sim.worlds.episode import FAMILY_SETUPS, Episode
from riskmap.sim.records.metrics import centre_off_lane
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS, Plan
from riskmap.sim.loop.rollout import LoopConfig, drive_world
from riskmap.sim.drivers.yielding import demonstrator


@dataclass(frozen=True)
class HumanLog:
    """One recorded human episode at `dt_s` per step (world frame, toolkit conventions).

    states [A, S, 6] (x, y, heading_x, heading_y, speed, yaw_rate), valid [A, S], sizes [A, 2]
    (length, width, m), kinds [A]; agent `ego_id` is the human ego.
    """

    states: np.ndarray
    valid: np.ndarray
    sizes: np.ndarray
    kinds: np.ndarray
    ego_id: int
    dt_s: float
    crashed: bool
    off_road: bool

    @property
    def num_steps(self) -> int:
        return self.states.shape[1]

    def ego_xy(self) -> np.ndarray:
        """The human ego's positions [S_valid, 2] over the steps it was recorded (from step 0)."""
        valid = self.valid[self.ego_id]
        end = int(np.argmin(valid)) if not valid.all() else len(valid)
        return self.states[self.ego_id, :end, :2]

    def tracks(self) -> Tracks:
        """The log's arrays as `Tracks` (not copied; no ids)."""
        return Tracks(self.states, self.valid, self.sizes, self.kinds)

    def save(self, path: Path) -> None:
        write_npz(path, {"states": self.states, "valid": self.valid, "sizes": self.sizes,
                         "kinds": self.kinds, "ego_id": np.int64(self.ego_id),
                         "dt_s": np.float64(self.dt_s), "crashed": np.bool_(self.crashed),
                         "off_road": np.bool_(self.off_road)})

    @classmethod
    def load(cls, path: Path) -> HumanLog:
        try:
            with np.load(path) as data:
                return cls(data["states"], data["valid"], data["sizes"], data["kinds"],
                           int(data["ego_id"]), float(data["dt_s"]), bool(data["crashed"]),
                           bool(data["off_road"]))
        except (OSError, KeyError, ValueError) as err:
            raise InputError(f"recorded episode {path} is unreadable ({err}); delete it and "
                             "rerun with --resume") from None


def log_of(run: Episode) -> HumanLog:
    """The HumanLog of an episode that has been driven."""
    tracks = run.recorder.tracks()
    return HumanLog(tracks.states.copy(), tracks.valid.copy(), tracks.sizes.copy(), tracks.kinds.copy(),
                    run.recorder.ego_id,
                    run.dt, bool(run.crashed), bool(run.off_network))


def record_human_episode(env, env_id: str, seed: int, episode: int, rate_hz: int,
                         episode_s: float) -> HumanLog:
    """Drive the family's demonstrator (the human: IDM/MOBIL, or the yielding teacher at
    intersections) on (seed, episode) for `episode_s` (or until it crashes / leaves)."""
    run = Episode(env, env_id, seed, episode, rate_hz)
    drive_world(run, demonstrator(FAMILY_SETUPS[family_of_env(env_id)].teacher), LoopConfig(round(episode_s * rate_hz), replan_every=1))
    return log_of(run)


def replay_vehicle_class():
    """A highway-env Vehicle whose state is its recorded track at the episode's current step."""
    from highway_env.vehicle.kinematics import Vehicle

    class ReplayVehicle(Vehicle):
        def __init__(self, road, track: np.ndarray, size: np.ndarray, clock, step: int):
            self.track, self.clock = track, clock
            self.route = None       # the route rule reads it where this vehicle is the ego
            super().__init__(road, np.zeros(2), 0.0, 0.0)
            self.LENGTH, self.WIDTH = float(size[0]), float(size[1])
            self.diagonal = float(np.hypot(self.LENGTH, self.WIDTH))
            self.set_step(step)

        def set_step(self, step: int) -> None:
            state = self.track[step]
            self.position = highway_env_from_world(state[:2])
            self.heading = float(-np.arctan2(state[3], state[2]))   # highway-env: clockwise
            self.speed = float(state[4])
            self.on_state_update()

        def act(self, action=None) -> None:
            pass

        def command(self, accel: float, steer_ccw: float) -> None:
            pass                                  # a replayed ego ignores the planner's commands

        def step(self, dt: float) -> None:
            if self.impact is not None:
                # highway-env registers a crash found one step ahead (an "impact") when the
                # vehicle next moves; the recorded human's crash was registered that way too.
                self.crashed, self.impact = True, None
            self.set_step(self.clock.next_step)

        def predict_trajectory_constant_speed(self, times: np.ndarray):
            # The intersection's right-of-way rule asks every vehicle for this; the base class
            # simulates a deep copy, which would copy the whole replayed episode.
            direction = np.array([np.cos(self.heading), np.sin(self.heading)])
            positions = [self.position + self.speed * t * direction for t in times]
            return positions, [self.heading] * len(times)

    return ReplayVehicle


class LogReplayEpisode(Episode):
    """The episode of `log` with every other vehicle replaying its record (see module docstring).

    With `replay_ego`, the vehicle the ego is handed to replays the human's own record too (log
    playback; the planner's commands are ignored). `next_step` is the record step being stepped to.
    `static_agents`: the number of static vehicles the log was recorded with (`Episode`); the
    reset places them again, and they replay their records like every other vehicle.
    """

    def __init__(self, env, env_id: str, seed: int, episode: int, log: HumanLog, rate_hz: int = CONTROL_HZ,
                 replay_ego: bool = False, static_agents: int = 0):
        super().__init__(env, env_id, seed, episode, rate_hz, static_agents=static_agents)
        if abs(log.dt_s - self.dt) > 1e-9:
            raise InputError(f"recorded episode has dt {log.dt_s} s, the replay steps {self.dt} s")
        self.log, self.replay_ego = log, replay_ego
        self.next_step = 0
        self._replayed: dict[int, object] = {}     # log agent -> its ReplayVehicle on the road
        self._replays: list[tuple[object, int]] = []   # every (ReplayVehicle, log agent) ever made
        self._cls = replay_vehicle_class()
        road, ego = self.base.road, self.ego
        ego_xy = self.recorder.latest_state(self.recorder.ego_id)[:2]
        if np.abs(log.states[log.ego_id, 0, :2] - ego_xy).max() > 1e-6:
            raise InputError("the recorded episode does not start where this episode does; it was "
                             "recorded with another env, seed or episode")
        # The vehicles at step 0 are the ones the record starts with, recorded in the same order
        # by the same reset, so each has its log agent's id: its replay continues that agent.
        for vehicle in [v for v in road.vehicles if v is not ego]:
            agent = self.recorder.known_id(vehicle)
            road.vehicles.remove(vehicle)
            if agent is None or agent >= len(log.sizes) or not log.valid[agent, 0]:
                continue
            xy = world_from_highway_env(vehicle.position)
            if np.abs(log.states[agent, 0, :2] - xy).max() > 1e-6:
                raise InputError("the recorded episode's vehicles do not start where this episode's "
                                 "do; it was recorded with another env, seed or episode")
            self.recorder.adopt(self._add(agent, 0), vehicle)
        starting = {int(a) for a in np.flatnonzero(log.valid[:, 0]) if a != log.ego_id}
        if starting - set(self._replayed):
            raise InputError("the recorded episode starts with vehicles this episode lacks; it was "
                             "recorded with another env, seed, episode or number of static vehicles")

    def _add(self, agent: int, step: int):
        vehicle = self._cls(self.base.road, self.log.states[agent], self.log.sizes[agent], self, step)
        self.base.road.vehicles.append(vehicle)
        self._replayed[agent] = vehicle
        self._replays.append((vehicle, agent))
        return vehicle

    def log_ids(self) -> np.ndarray:
        """[A]: the log agent each recorder agent replays (the ego: the log's ego; -1: none).

        Known by construction, since every replayed vehicle is made for one log agent: the
        rollout keeps agent ids, nothing is matched by position afterwards."""
        ids = np.full(self.recorder.tracks().num_agents, -1, dtype=np.int64)
        for vehicle, agent in self._replays:
            recorder_id = self.recorder.known_id(vehicle)
            if recorder_id is not None:
                ids[recorder_id] = agent
        ids[self.recorder.ego_id] = self.log.ego_id
        return ids

    def replace_ego(self, vehicle) -> None:
        if self.replay_ego:
            old = self.ego
            vehicle = self._cls(old.road, self.log.states[self.log.ego_id], self.log.sizes[self.log.ego_id],
                                self, self.steps)
            vehicle.route = list(old.route) if old.route else None
        super().replace_ego(vehicle)

    @property
    def done(self) -> bool:
        return super().done or self.steps >= self.log.num_steps - 1

    def step(self) -> None:
        if self.steps >= self.log.num_steps - 1:
            raise InputError("the recorded episode has ended; nothing left to replay")
        road, ego = self.base.road, self.ego
        self.next_step = k = self.steps + 1
        present = {int(a) for a in np.flatnonzero(self.log.valid[:, k]) if a != self.log.ego_id}
        for agent in list(self._replayed):
            if agent not in present:
                road.vehicles.remove(self._replayed.pop(agent))
        for agent in sorted(present - set(self._replayed)):
            self._add(agent, k)
        road.act()
        road.step(self.dt)
        self.steps = k
        self.recorder.record()
        if ego.crashed:
            self.crashed = True
            return
        if self.steps % self.rate_hz == 0:
            self.off_network = centre_off_lane(road, ego)


class ReplayPlanner:
    """`replay`: the human's recorded trajectory as the plan (log playback).

    Needs the recorded episode: it declares `requires_log`, and whoever drives it hands the log
    over with `set_log` (nuPlan's `requires_scenario`). Meaningful only where the traffic replays
    that same record (`riskmap evaluate --mode log`); with reactive traffic the record no longer fits.
    """

    requires_log = True       # set_log(HumanLog) before driving; the ego replays the record

    def __init__(self):
        self._times_s = self._xy = None

    def set_log(self, log: HumanLog) -> None:
        xy = log.ego_xy()
        self._times_s = log.dt_s * np.arange(len(xy))
        self._xy = xy

    def reset(self, scene: Scene) -> None:
        if self._xy is None:
            raise InputError("planner `replay` needs a recorded episode; use it with "
                             "`riskmap evaluate --mode log`")

    def plan(self, scene: Scene) -> Plan:
        if self._xy is None:
            raise InputError("planner `replay` needs a recorded episode; use it with "
                             "`riskmap evaluate --mode log`")
        t = scene.time_s + PLAN_DT_S * np.arange(1, PLAN_STEPS + 1)
        xy = np.stack([np.interp(t, self._times_s, self._xy[:, 0]),
                       np.interp(t, self._times_s, self._xy[:, 1])], axis=1)
        state = scene.ego_state()
        return Plan(ego_from_world(xy, state[:2], float(heading_angle(state[2:4]))))
