"""Recorded tracks: every dynamic obstacle of a scenario on the file's time grid
(`RecordedTraffic`), and the Scene around one of them at a recorded step."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from rasterize.commonroad.config import CommonRoadSceneConfig
from rasterize.commonroad.lanes import lanes_from_lanelets
from rasterize.commonroad.lights import LaneletLight, lanelet_lights, lights_in_extent
from rasterize.commonroad.route import route_on_lanelets
from rasterize.errors import InputError
from rasterize.scene import STATE_DIM, AgentKind, Lane, Scene, Signal

# Obstacle types that drive: they may be demonstrators, and they are VEHICLE agents.
VEHICLE_TYPES = ("car", "truck", "bus", "motorcycle", "taxi", "priorityVehicle")


def _box_of(shape) -> tuple[float, float]:
    """(length, width) in metres of an obstacle's shape: a rectangle's own, else its bounding box."""
    if hasattr(shape, "length") and hasattr(shape, "width"):
        return float(shape.length), float(shape.width)
    if hasattr(shape, "radius"):
        return 2.0 * float(shape.radius), 2.0 * float(shape.radius)
    vertices = np.asarray(getattr(shape, "vertices", np.zeros((2, 2))))
    extent = vertices.max(axis=0) - vertices.min(axis=0)
    return float(max(extent[0], 0.1)), float(max(extent[1], 0.1))


def _recorded_states(obstacle) -> list:
    states = [obstacle.initial_state]
    prediction = getattr(obstacle, "prediction", None)
    trajectory = getattr(prediction, "trajectory", None)
    if trajectory is not None:
        states += list(trajectory.state_list)
    return sorted(states, key=lambda s: int(s.time_step))


MAX_SPEED_MPS = 70.0     # a recorded step implying more than this is a jump, not driving


class SetBasedRecording(InputError):
    """A CommonRoad file whose states are sets (intervals, shapes: the `_S-1` scenarios) rather
    than recorded trajectories; nothing can be replayed or learned from it."""


def _is_exact(state) -> bool:
    """Whether a CommonRoad state is a recorded point: a 2-vector position and plain numbers."""
    position = getattr(state, "position", None)
    if not (isinstance(position, np.ndarray) and position.shape == (2,)):
        return False
    return all(isinstance(getattr(state, name, None), (int, float, np.number, type(None)))
               for name in ("orientation", "velocity"))


def _track_problem(record: list, dt_s: float) -> str:
    """Why a recorded track cannot be used ("" when it can): non-finite values or a jump."""
    steps = np.array([int(st.time_step) for st in record])
    xy = np.array([np.asarray(st.position, dtype=np.float64).reshape(-1)[:2] for st in record])
    for name in ("orientation", "velocity"):
        values = [getattr(st, name, None) for st in record]
        if any(v is not None and not np.isfinite(float(v)) for v in values):
            return f"non-finite {name}"
    if not np.isfinite(xy).all():
        return "non-finite position"
    if len(steps) > 1:
        speed = np.linalg.norm(np.diff(xy, axis=0), axis=1) / (np.diff(steps) * dt_s)
        if speed.max() > MAX_SPEED_MPS:
            return f"jump of {speed.max() * dt_s:.1f} m in one step"
    return ""


def smooth_track(states: np.ndarray, dt_s: float, window_s: float) -> np.ndarray:
    """[S, 6] states of one track with positions, heading and speed smoothed (class doc).

    Quadratic Savitzky-Golay over the odd number of steps closest to `window_s` (at most the
    track's length); the yaw rate is recomputed from the smoothed heading as a backward
    difference. Tracks shorter than 5 steps are returned unchanged.
    """
    from scipy.signal import savgol_filter

    n = len(states)
    window = min(int(round(window_s / dt_s)) | 1, n if n % 2 else n - 1)
    if window < 5:
        return states
    out = states.copy()
    out[:, :2] = savgol_filter(states[:, :2], window, 2, axis=0, mode="interp")
    heading = savgol_filter(np.unwrap(np.arctan2(states[:, 3], states[:, 2])), window, 2,
                            mode="interp")
    velocity = savgol_filter(states[:, :2], window, 2, deriv=1, delta=dt_s, axis=0, mode="interp")
    out[:, 2], out[:, 3] = np.cos(heading), np.sin(heading)
    out[:, 4] = np.linalg.norm(velocity, axis=1)
    out[:, 5] = np.concatenate([[states[0, 5]], np.diff(heading) / dt_s])
    return out


class RecordedTraffic:
    """Every dynamic obstacle of a scenario on the file's time grid.

    Shapes: A obstacles, S = last time step + 1 of the recording.
        states [A, S, 6] (x, y, heading_x, heading_y, speed, yaw_rate), valid [A, S],
        sizes [A, 2], kinds [A], ids [A] (CommonRoad obstacle ids), is_vehicle [A].
    The yaw rate is the backward difference of the recorded heading (0 at a vehicle's first
    step), as the simulator's recorder computes it; a speed missing from the file is the
    displacement rate.

    `smoothing_s` > 0 smooths every track (NGSIM positions jump by decimetres between steps,
    which reads as 7 m/s² accelerations at the 99th percentile): positions and the unwrapped
    heading by a Savitzky-Golay filter (quadratic) over that many seconds, the speed as the
    same filter's derivative of the positions, so speed and displacement agree.
    A vehicle whose record is not finite or jumps (a step implying more than `MAX_SPEED_MPS`)
    cannot be placed: it is left out of the arrays and its id listed in `rejected` with why.

    `lights`: the lanelet network's (lanelet, traffic light) pairs with a known cycle
    (`lanelet_lights`), `lights_by_lanelet` the same by lanelet id.
    """

    def __init__(self, scenario, name: str = "", smoothing_s: float = 0.0):
        self.scenario, self.name = scenario, name or str(getattr(scenario, "scenario_id", ""))
        self.dt_s = float(scenario.dt)
        self.smoothing_s = float(smoothing_s)
        self.rejected: dict[int, str] = {}
        self.lights = lanelet_lights(scenario.lanelet_network, self.dt_s, self.name)
        self.lights_by_lanelet: dict[int, tuple[LaneletLight, ...]] = {}
        for light in self.lights:
            self.lights_by_lanelet[light.lanelet_id] = self.lights_by_lanelet.get(light.lanelet_id, ()) + (light,)
        self._lanelet_counts: dict[int, Counter] = {}
        obstacles, records = [], []
        for obstacle in sorted(scenario.dynamic_obstacles, key=lambda o: o.obstacle_id):
            record = _recorded_states(obstacle)
            if not all(map(_is_exact, record)):
                raise SetBasedRecording(
                    f"CommonRoad scenario {self.name} is set-based (obstacle {obstacle.obstacle_id} "
                    "has interval or shape states, as in _S-1 files), not a recorded trajectory; "
                    "pass the trajectory files (_T-1)")
            problem = _track_problem(record, self.dt_s)
            if problem:
                self.rejected[int(obstacle.obstacle_id)] = problem
            else:
                obstacles.append(obstacle)
                records.append(record)
        last = max((int(r[-1].time_step) for r in records), default=0)
        n, s = len(obstacles), last + 1
        self.states = np.zeros((n, s, STATE_DIM))
        self.valid = np.zeros((n, s), dtype=bool)
        self.sizes = np.array([_box_of(o.obstacle_shape) for o in obstacles]).reshape(n, 2)
        self.ids = np.array([o.obstacle_id for o in obstacles], dtype=np.int64)
        self.is_vehicle = np.array([o.obstacle_type.value in VEHICLE_TYPES for o in obstacles], bool)
        self.kinds = np.where(self.is_vehicle, AgentKind.VEHICLE, AgentKind.OBSTACLE).astype(np.int8)
        for a, record in enumerate(records):
            steps = np.array([int(st.time_step) for st in record])
            xy = np.array([np.asarray(st.position, dtype=np.float64) for st in record])
            orientation = [getattr(st, "orientation", None) for st in record]
            heading = np.array([np.nan if o is None else float(o) for o in orientation])
            if np.isnan(heading).any():  # no orientation recorded: the direction of motion
                d = np.gradient(xy, axis=0) if len(xy) > 1 else np.array([[1.0, 0.0]])
                heading = np.arctan2(d[:, 1], d[:, 0])
            heading = np.unwrap(heading)
            speed = np.array([np.nan if getattr(st, "velocity", None) is None
                              else float(st.velocity) for st in record])
            if np.isnan(speed).any():
                speed = (np.linalg.norm(np.gradient(xy, axis=0), axis=1) / self.dt_s
                         if len(xy) > 1 else np.zeros(1))
            yaw_rate = np.concatenate([[0.0], np.diff(heading) / (np.diff(steps) * self.dt_s)])
            self.states[a, steps] = np.column_stack([xy, np.cos(heading), np.sin(heading), speed,
                                                     yaw_rate])
            # The record may skip steps; those are filled by interpolation, so mark the span.
            self.valid[a, steps[0]: steps[-1] + 1] = True
            gaps = np.setdiff1d(np.arange(steps[0], steps[-1] + 1), steps)
            if gaps.size:
                for k in range(STATE_DIM):
                    self.states[a, gaps, k] = np.interp(gaps, steps, self.states[a, steps, k])
            if self.smoothing_s > 0:
                first, last = steps[0], steps[-1] + 1
                self.states[a, first:last] = smooth_track(self.states[a, first:last], self.dt_s,
                                                          self.smoothing_s)

    @property
    def num_steps(self) -> int:
        return self.states.shape[1]

    def index_of(self, obstacle_id: int) -> int:
        hits = np.flatnonzero(self.ids == int(obstacle_id))
        if hits.size == 0:
            raise InputError(f"ego id {obstacle_id} is not a dynamic obstacle of {self.name}; "
                             f"choose one of its {len(self.ids)} ids "
                             f"({', '.join(map(str, self.ids[:8]))}{', ...' if len(self.ids) > 8 else ''})")
        return int(hits[0])

    def span(self, agent: int) -> tuple[int, int]:
        """First and last recorded time step of an agent."""
        steps = np.flatnonzero(self.valid[agent])
        return int(steps[0]), int(steps[-1])

    def resample(self, agents: np.ndarray, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States [len(agents), len(times_s), 6] and validity at arbitrary times (seconds from the
        recording's step 0), by linear interpolation between recorded steps; heading by angle."""
        out = np.zeros((len(agents), len(times_s), STATE_DIM))
        valid = np.zeros((len(agents), len(times_s)), dtype=bool)
        for i, agent in enumerate(agents):
            first, last = self.span(agent)
            t_rec = np.arange(first, last + 1) * self.dt_s
            inside = (times_s >= t_rec[0] - 1e-9) & (times_s <= t_rec[-1] + 1e-9)
            if not inside.any():
                continue
            t = times_s[inside]
            rec = self.states[agent, first: last + 1]
            angle = np.unwrap(np.arctan2(rec[:, 3], rec[:, 2]))
            theta = np.interp(t, t_rec, angle)
            out[i, inside] = np.column_stack([
                np.interp(t, t_rec, rec[:, 0]), np.interp(t, t_rec, rec[:, 1]),
                np.cos(theta), np.sin(theta),
                np.interp(t, t_rec, rec[:, 4]), np.interp(t, t_rec, rec[:, 5]),
            ])
            valid[i, inside] = True
        return out, valid

    def lanelet_counts(self, agent: int) -> Counter:
        """How many of the agent's recorded positions lie in each lanelet (lanelet id -> count)."""
        if agent not in self._lanelet_counts:
            first, last = self.span(agent)
            points = [p for p in self.states[agent, first: last + 1, :2]]
            found = self.scenario.lanelet_network.find_lanelet_by_position(points)
            self._lanelet_counts[agent] = Counter(int(i) for ids in found for i in ids)
        return self._lanelet_counts[agent]

    def successor_taken(self, agent: int, successors: Sequence[int]) -> int:
        """Of a lanelet's `successors`, the one recorded vehicle `agent` took: the one holding most
        of its recorded positions (the lowest id when it reaches none of them in its record)."""
        counts = self.lanelet_counts(agent)
        return max(sorted(successors), key=lambda s: (counts.get(int(s), 0), -int(s)))

    def route(self, agent: int, state: np.ndarray, others: np.ndarray, other_lengths_m: np.ndarray,
              now_s: float, config: CommonRoadSceneConfig) -> np.ndarray:
        """The route rule's route [points, 2] for recorded vehicle `agent` in `state` at `now_s`
        (seconds from step 0) among `others` [M, 6]: on the lanelets it was recorded to use
        (where lanelets overlap) and through intersections the way it was recorded to go, held
        before a red light (`route_on_lanelets`)."""
        return route_on_lanelets(self.scenario.lanelet_network, state, self.sizes[agent, 0], others,
                                 other_lengths_m, config.route_rule, config.speed_limit_mps,
                                 successor=lambda succ: self.successor_taken(agent, succ),
                                 rank=lambda lanelet_id: self.lanelet_counts(agent).get(lanelet_id, 0),
                                 lights=self.lights_by_lanelet, now_s=now_s,
                                 stop_gap_m=config.stop_gap_m)

    def scene_signals(self, ego_state: np.ndarray, now_s: float,
                      config: CommonRoadSceneConfig) -> tuple[Signal, ...]:
        """One `Signal` per (lanelet, light) whose stop line lies within the scene's extent around
        `ego_state`, its state every `config.dt_s` from `now_s` (s from step 0) to `future_s`."""
        times = config.dt_s * np.arange(0, int(np.floor(config.future_s / config.dt_s + 1e-9)) + 1)
        return tuple(light.signal(now_s, times) for light in
                     lights_in_extent(self.lights, ego_state, config.extent, config.lane_radius_m))

    def window_steps(self, agent: int, config: CommonRoadSceneConfig, stride_s: float) -> list[int]:
        """Current time steps at which `agent` has its full history and future recorded, one every
        `stride_s` from its first possible step."""
        first, last = self.span(agent)
        hist = config.history_s / self.dt_s
        fut = config.future_s / self.dt_s
        stride = max(1, round(stride_s / self.dt_s))
        start = first + int(np.ceil(hist - 1e-9))
        return list(range(start, int(np.floor(last - fut + 1e-9)) + 1, stride))

    def scene(self, ego: int, time_index: int, config: CommonRoadSceneConfig = CommonRoadSceneConfig(),
              lanes: tuple[Lane, ...] | None = None) -> Scene:
        """The Scene around agent index `ego` at recorded step `time_index` (see the module doc)."""
        if not 0 <= time_index < self.num_steps:
            raise InputError(f"time index {time_index} is outside the recording of {self.name} "
                             f"(0..{self.num_steps - 1} steps of {self.dt_s} s)")
        if not self.valid[ego, time_index]:
            first, last = self.span(ego)
            raise InputError(f"vehicle {self.ids[ego]} is not on the road at time index {time_index} "
                             f"of {self.name}; it is recorded from step {first} to {last}")
        now_s = time_index * self.dt_s
        ego_xy = self.states[ego, time_index, :2]
        present = [a for a in np.flatnonzero(self.valid[:, time_index]) if a != ego]
        dist = np.array([np.linalg.norm(self.states[a, time_index, :2] - ego_xy) for a in present])
        order = [present[i] for i in np.argsort(dist, kind="stable") if dist[i] <= config.radius_m]
        agents = np.array([ego] + order[: config.max_agents - 1], dtype=np.int64)
        times = now_s + config.dt_s * np.arange(-config.history_steps, config.future_steps + 1)
        states, valid = self.resample(agents, times)
        network = self.scenario.lanelet_network
        if lanes is None:
            lanes = lanes_from_lanelets(network, ego_xy, config.lane_radius_m)
        route = self.route(ego, self.states[ego, time_index], self.states[agents[1:], time_index],
                           self.sizes[agents[1:], 0], now_s, config)
        return Scene(states, valid, self.sizes[agents], self.kinds[agents], ego_index=0,
                     current_index=config.history_steps, dt=config.dt_s, lanes=lanes,
                     source=f"commonroad:{self.name}", time_s=now_s, route_xy=route,
                     signals=self.scene_signals(self.states[ego, time_index], now_s, config))
