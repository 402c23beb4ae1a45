"""Scenes from highway-env: lanes from any road network, and a recorder of every vehicle.

highway-env's frame has y pointing down the screen; everything here leaves in the toolkit's
right-handed world frame (`rasterize.frames.world_from_highway_env`). Lane samplers call only the
`AbstractLane` interface (`position`, `width_at`, `local_coordinates`, `length`, `line_types`), so
straight, sine, circular and poly lanes all work.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import cv2
import numpy as np

from rasterize.errors import InputError
from rasterize.frames import heading_from_highway_env, world_from_highway_env
from rasterize.scene import STATE_DIM, AgentKind, Lane, LineType, Scene
from rasterize.timebase import FUTURE_S, HISTORY_S, PLAN_DT_S
from rasterize.tracks import Tracks


@dataclass(frozen=True)
class LaneSampling:
    """How lanes are cut out of a road network around the ego."""

    radius_m: float = 260.0     # keep lane points within this distance of the ego
    step_m: float = 1.0         # arc-length spacing of samples on curved lanes
    simplify_m: float = 0.02    # polyline simplification tolerance


def _sample_lane(lane, s_values: np.ndarray) -> Lane:
    centre, left, right = [], [], []
    for s in s_values:
        half = 0.5 * lane.width_at(s)
        centre.append(lane.position(s, 0.0))
        left.append(lane.position(s, -half))   # negative lateral is the left side in highway-env
        right.append(lane.position(s, half))
    centre, left, right = (world_from_highway_env(np.asarray(p)) for p in (centre, left, right))
    line_left, line_right = (LineType(int(t)) for t in lane.line_types)
    return Lane(centre, left, right, line_left, line_right, float(lane.width_at(s_values[0])),
                float(s_values[0]))


def _sample_straight_lane(lane, s_values: np.ndarray) -> Lane:
    """`_sample_lane` of a highway-env `StraightLane`, all points at once: `StraightLane.position`
    is start + s * direction + lateral * lateral_direction, here with the same elementwise
    operations on arrays, so the points are the same."""
    s = np.asarray(s_values, dtype=np.float64)[:, None]
    half = 0.5 * lane.width_at(s_values[0])       # a straight lane's width is the same everywhere
    along = lane.start + s * lane.direction
    centre, left, right = (world_from_highway_env(along + lateral * lane.direction_lateral)
                           for lateral in (0.0, -half, half))
    line_left, line_right = (LineType(int(t)) for t in lane.line_types)
    return Lane(centre, left, right, line_left, line_right, float(lane.width_at(s_values[0])),
                float(s_values[0]))


def _sample_circular_lane(lane, s_values: np.ndarray) -> Lane:
    """`_sample_lane` of a highway-env `CircularLane`: `CircularLane.position` is centre +
    (radius - lateral * direction) * [cos phi, sin phi] with phi from s alone, so the cosine and
    sine of each s (taken point by point, as there) serve its three points; the rest is the same
    elementwise arithmetic on arrays, so the points are the same."""
    s = np.asarray(s_values, dtype=np.float64)
    phis = lane.direction * s / lane.radius + lane.start_phase
    unit = np.array([np.array([np.cos(phi), np.sin(phi)]) for phi in phis]).reshape(-1, 2)
    half = 0.5 * lane.width_at(s_values[0])       # a circular lane's width is the same everywhere
    centre, left, right = (world_from_highway_env(lane.center + (lane.radius - lateral * lane.direction)
                                                  * unit)
                           for lateral in (0.0, -half, half))
    line_left, line_right = (LineType(int(t)) for t in lane.line_types)
    return Lane(centre, left, right, line_left, line_right, float(lane.width_at(s_values[0])),
                float(s_values[0]))


def _simplify(lane: Lane, tolerance_m: float) -> Lane:
    """Drop samples that the centre line does not need (straight stretches keep 2 points)."""
    if lane.centre.shape[0] <= 2:
        return lane
    keep = cv2.approxPolyDP(
        (lane.centre * 1000.0).astype(np.float32).reshape(-1, 1, 2), tolerance_m * 1000.0, False
    )
    # approxPolyDP returns points, not indices: recover them (they are exact copies).
    scaled = (lane.centre * 1000.0).astype(np.float32)
    idx = []
    start = 0
    for p in keep.reshape(-1, 2):
        j = start + int(np.argmin(np.abs(scaled[start:] - p).sum(axis=1)))
        idx.append(j)
        start = j
    idx = np.unique(np.asarray(idx + [0, lane.centre.shape[0] - 1]))
    return Lane(lane.centre[idx], lane.left[idx], lane.right[idx], lane.left_line,
                lane.right_line, lane.width_m, lane.start_s)


def lanes_near(network, centre_world: np.ndarray, sampling: LaneSampling = LaneSampling()
               ) -> tuple[Lane, ...]:
    """Every lane of a highway-env `RoadNetwork` that comes within `sampling.radius_m` of a point.

    Long lanes are sampled only over the arc-length window that can reach the point.
    """
    centre_hw = world_from_highway_env(centre_world)
    radius = sampling.radius_m
    batch = {}
    if getattr(network, "fast_road", False):     # riskmap.sim.worlds.fast_road: the same points, at once
        from highway_env.road.lane import CircularLane, StraightLane

        batch = {StraightLane: _sample_straight_lane, CircularLane: _sample_circular_lane}
    lanes = []
    for _from, tos in network.graph.items():
        for _to, lane_list in tos.items():
            for lane in lane_list:
                length = float(lane.length)
                if length <= 2 * radius:
                    lo, hi = 0.0, length
                else:
                    s_here = float(lane.local_coordinates(centre_hw)[0])
                    lo, hi = max(0.0, s_here - radius), min(length, s_here + radius)
                    if hi - lo < 1e-6:
                        continue
                n = max(2, int(np.ceil((hi - lo) / sampling.step_m)) + 1)
                s_values = np.linspace(lo, hi, n)
                sampled = batch.get(type(lane), _sample_lane)(lane, s_values)
                if np.linalg.norm(sampled.centre - centre_world, axis=1).min() > radius:
                    continue
                lanes.append(_simplify(sampled, sampling.simplify_m))
    return tuple(lanes)


@dataclass(frozen=True)
class RouteRule:
    """Where the planner is sent: along the ego's route, as far as it could get in `horizon_s`.

    free distance = min(speed_limit × horizon, speed × horizon + accel × horizon² / 2): keep the
    speed and gain `accel_mps2` up to the lane's speed limit, so a stopped ego still gets a goal
    ahead and a fast one is not sent beyond the limit. A leader on the route (a vehicle within
    `lane_half_width_m` of it, ahead) caps the distance at where the leader will be after
    `horizon_s` at its current speed, less a standstill gap and a time headway. Present
    information only; used alike for training goal maps and in closed loop.
    """

    horizon_s: float = FUTURE_S
    accel_mps2: float = 1.0
    standstill_gap_m: float = 5.0
    headway_s: float = 1.5
    lane_half_width_m: float = 2.0
    points: int = 13          # samples from the ego (distance 0) to the goal, evenly spaced
    sample_m: float = 2.0     # spacing of the route samples used to find a leader


def _route_lanes(network, vehicle, length_needed: float) -> list:
    """The lane indices the vehicle will follow: its planned route, else straight-on successors."""
    route = [vehicle.lane_index]
    planned = [idx for idx in (vehicle.route or []) if idx[:2] != vehicle.lane_index[:2]]
    for _from, _to, lane_id in planned:
        # Resolve unspecified lanes here: highway-env checks the id against the wrong segment.
        n_lanes = len(network.graph[_from][_to])
        keep = route[-1][2] if lane_id is None else lane_id
        route.append((_from, _to, min(keep, n_lanes - 1)))
    total = network.get_lane(vehicle.lane_index).length
    while not planned and total < length_needed:
        _from, _to, lane_id = route[-1]
        successors = sorted(network.graph.get(_to, {}).keys())
        if not successors:
            break
        nxt = successors[0]
        ids = len(network.graph[_to][nxt])
        route.append((_to, nxt, lane_id if lane_id < ids else ids - 1))
        total += network.get_lane(route[-1]).length
        if len(route) > 50:
            break
    return route


def route_ahead(road, vehicle, rule: RouteRule = RouteRule()) -> np.ndarray:
    """[rule.points, 2] world points along the vehicle's route, from it to its goal (see RouteRule)."""
    network = road.network
    lane = network.get_lane(vehicle.lane_index)
    speed = max(float(vehicle.speed), 0.0)
    limit = float(getattr(lane, "speed_limit", None) or speed or 10.0)
    t = rule.horizon_s
    free = min(limit * t, speed * t + 0.5 * rule.accel_mps2 * t * t)
    reach = free + 40.0                                   # look for leaders a little further
    s0 = float(lane.local_coordinates(vehicle.position)[0])
    route = _route_lanes(network, vehicle, s0 + reach)
    along = np.arange(0.0, reach + rule.sample_m, rule.sample_m)
    # A fast road (riskmap.sim.worlds.fast_road) gives the same points and the same leaders with less
    # work: its network places the route's straight stretches at once, and only the vehicles that
    # come within lane_half_width_m of the route (with a margin) are examined.
    fast = bool(getattr(road, "fast_road", False)) and hasattr(network, "positions_along_route")
    if fast:
        dense = network.positions_along_route(route, s0 + along, vehicle.lane_index, 0.0)
    else:
        dense = np.asarray([network.position_heading_along_route(route, s0 + d, 0.0,
                                                                 vehicle.lane_index)[0] for d in along])
    dense[0] = vehicle.position
    distance = free
    for other in _maybe_leaders(road, vehicle, dense, rule.lane_half_width_m) if fast else road.vehicles:
        if other is vehicle or np.linalg.norm(other.position - vehicle.position) > reach + 10.0:
            continue
        offsets = np.linalg.norm(dense - other.position, axis=1)
        j = int(np.argmin(offsets))
        if j == 0 or offsets[j] > rule.lane_half_width_m:
            continue                                      # beside or behind, or off the route
        direction = dense[min(j + 1, len(dense) - 1)] - dense[max(j - 1, 0)]
        direction /= max(np.linalg.norm(direction), 1e-9)
        v_lead = max(0.0, float(np.dot(other.velocity, direction)))
        gap = along[j] - 0.5 * (vehicle.LENGTH + other.LENGTH)
        cap = gap + v_lead * t - (rule.standstill_gap_m + v_lead * rule.headway_s)
        distance = min(distance, max(0.0, cap))
    ds = np.linspace(0.0, distance, rule.points)
    pts = np.stack([np.interp(ds, along, dense[:, 0]), np.interp(ds, along, dense[:, 1])], axis=1)
    return world_from_highway_env(pts)


def _maybe_leaders(road, vehicle, dense: np.ndarray, half_width_m: float) -> list:
    """The vehicles of `road` (in its order) that come within `half_width_m` of a point of
    `dense`, up to a rounding margin: the others cannot be leaders in `route_ahead`."""
    others = [v for v in road.vehicles if v is not vehicle]
    if not others:
        return []
    try:
        positions = np.array([v.position for v in others], dtype=np.float64)
    except (TypeError, ValueError):
        return list(road.vehicles)
    if positions.shape != (len(others), 2):
        return list(road.vehicles)
    diff = dense[None, :, :] - positions[:, None, :]
    nearest = np.sqrt((diff * diff).sum(axis=-1)).min(axis=1)
    near = ~(nearest > half_width_m + 1e-6 + 1e-12 * np.abs(positions).sum(axis=1))
    return [v for v, keep in zip(others, near.tolist()) if keep]


class _Frozen:
    """A vehicle as `route_ahead` reads it, at the step it was copied."""

    __slots__ = ("LENGTH", "_velocity", "heading", "lane_index", "position", "route", "speed")

    @property
    def velocity(self) -> np.ndarray:
        # highway-env's Vehicle.velocity (speed * direction) of the copied speed and heading.
        if self._velocity is None:
            self._velocity = self.speed * np.array([np.cos(self.heading), np.sin(self.heading)])
        return self._velocity


class _RouteLater:
    """`route_ahead(road, ego, rule)` of the moment this was made, computed on `compute()` from
    copies of everything it reads: the ego's lane, route, position, speed and length, each other
    vehicle's position, velocity and length, in the road's order (the network does not change).
    A velocity that highway-env's own properties give is computed from the copied speed and
    heading when needed."""

    __slots__ = ("ego", "road", "route", "rule")

    def __init__(self, road, ego, rule: RouteRule):
        from types import SimpleNamespace

        from highway_env.vehicle.kinematics import Vehicle
        from highway_env.vehicle.objects import RoadObject

        def freeze(v) -> _Frozen:
            f = _Frozen()
            f.position, f.LENGTH, f.speed, f.heading, f._velocity = (np.array(v.position),
                                                                    v.LENGTH, v.speed, None, None)
            if v is ego:                       # route_ahead reads its lane and route, not its velocity
                f.lane_index, f.route = v.lane_index, list(v.route) if v.route else v.route
            elif type(v).velocity is Vehicle.velocity and type(v).direction is RoadObject.direction:
                f.heading = v.heading
            else:
                f._velocity = v.velocity
            return f

        vehicles = [freeze(v) for v in road.vehicles]
        self.ego = next((f for v, f in zip(road.vehicles, vehicles) if v is ego), None) or freeze(ego)
        self.road = SimpleNamespace(network=road.network, vehicles=vehicles,
                                    fast_road=getattr(road, "fast_road", False))
        self.rule, self.route = rule, None

    def compute(self) -> np.ndarray:
        if self.route is None:
            self.route = route_ahead(self.road, self.ego, self.rule)
        return self.route


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def _kind_of(obj) -> AgentKind:
    from highway_env.vehicle.kinematics import Vehicle

    return AgentKind.VEHICLE if isinstance(obj, Vehicle) else AgentKind.OBSTACLE


class TrafficRecorder:
    """Records every vehicle and object on a highway-env road at each call of `record`.

    Agents keep a stable integer id for as long as the recorder lives (vehicles that leave and
    are removed simply stop being valid). `scene(...)` cuts a `Scene` out of the record.
    """

    def __init__(self, road, ego, dt_s: float, route_rule: RouteRule | None = RouteRule()):
        if not dt_s > 0:
            raise InputError(f"TrafficRecorder dt_s must be positive seconds, got {dt_s}")
        self.road, self.ego, self.dt_s = road, ego, float(dt_s)
        self.route_rule = route_rule
        self._routes: dict[int, np.ndarray | _RouteLater] = {}   # step -> the ego's route ahead
        self._ids: dict[int, int] = {}          # id(vehicle object) -> agent id
        self._alive: list[object] = []          # keeps objects alive so ids are never reused
        self._rows: list[tuple[int, int, np.ndarray]] = []  # (step, agent, state[6])
        self._sizes: list[np.ndarray] = []
        self._kinds: list[int] = []
        self._last_heading: dict[int, tuple[int, float]] = {}
        self._latest: dict[int, np.ndarray] = {}   # agent -> its most recent state [6]
        self.num_steps = 0
        self._cache = None

    def known_id(self, obj) -> int | None:
        """The agent id `obj` is recorded under (its own, or the one it adopted), None if none."""
        return self._ids.get(id(obj))

    def _agent_id(self, obj) -> int:
        key = id(obj)
        if key not in self._ids:
            self._ids[key] = len(self._sizes)
            self._alive.append(obj)
            self._sizes.append(np.array([obj.LENGTH, obj.WIDTH], dtype=np.float64))
            self._kinds.append(int(_kind_of(obj)))
        return self._ids[key]

    def adopt(self, new, old) -> None:
        """`new` continues the recording of agent `old` (e.g. the ego handed to another driver)."""
        self._ids[id(new)] = self._agent_id(old)
        self._alive.append(new)
        if self.ego is old:
            self.ego = new

    @property
    def ego_id(self) -> int:
        return self._agent_id(self.ego)

    def record(self) -> None:
        """Append the current state of every vehicle and object on the road."""
        step = self.num_steps
        fast = getattr(self.road, "fast_road", False)
        for obj in list(self.road.vehicles) + list(self.road.objects):
            agent = self._agent_id(obj)
            position = obj.position
            if fast and type(position) is np.ndarray and position.dtype == np.float64 \
                    and position.shape == (2,):
                # The same numbers as below: the flip of y is a product by -1.0, of the
                # heading a negation.
                pos = (position[0], position[1] * -1.0)
                heading = -float(obj.heading)
            else:
                pos = world_from_highway_env(position)
                heading = float(heading_from_highway_env(obj.heading))
            prev = self._last_heading.get(agent)
            yaw_rate = (float(_wrap(heading - prev[1])) / self.dt_s
                        if prev is not None and prev[0] == step - 1 else 0.0)
            self._last_heading[agent] = (step, heading)
            speed = float(getattr(obj, "speed", 0.0))
            state = np.array([pos[0], pos[1], np.cos(heading), np.sin(heading), speed, yaw_rate])
            self._rows.append((step, agent, state))
            self._latest[agent] = state
        self.ego_id  # the ego is always known, even before it moves
        if self.route_rule is not None and getattr(self.ego, "lane_index", None) is not None:
            if getattr(self.road, "fast_road", False):
                # riskmap.sim.worlds.fast_road: keep what route_ahead reads, compute it if a scene asks.
                self._routes[step] = _RouteLater(self.road, self.ego, self.route_rule)
            else:
                self._routes[step] = route_ahead(self.road, self.ego, self.route_rule)
        self.num_steps += 1
        self._cache = None

    def latest_state(self, agent: int) -> np.ndarray:
        """The most recently recorded state [6] of `agent` (no rebuild of the whole record)."""
        return self._latest[agent]

    def tracks(self) -> Tracks:
        """The whole record as `Tracks` (states, valid, sizes, kinds; no ids): one row per recorded
        agent, its recorder id (a vehicle that took over an agent's recording, `adopt`, adds none)."""
        if self._cache is None:
            n_agents, n_steps = len(self._sizes), self.num_steps
            states = np.zeros((n_agents, n_steps, STATE_DIM))
            valid = np.zeros((n_agents, n_steps), dtype=bool)
            for step, agent, state in self._rows:
                states[agent, step] = state
                valid[agent, step] = True
            self._cache = Tracks(states, valid, np.asarray(self._sizes).reshape(-1, 2),
                                 np.asarray(self._kinds, dtype=np.int8))
        return self._cache

    def scene(self, step: int, history_s: float = HISTORY_S, future_s: float = FUTURE_S,
              dt_s: float = PLAN_DT_S, radius_m: float = 120.0, max_agents: int = 32, lanes: bool = True,
              sampling: LaneSampling = LaneSampling(), source: str = "") -> Scene:
        """The scene at recorded `step`, resampled every `dt_s` (a multiple of the record's dt).

        Agents: the ego first, then the others present at `step` within `radius_m` of the ego,
        nearest first, at most `max_agents` in all. Times outside the record are invalid.
        """
        stride = int(round(dt_s / self.dt_s))
        if stride < 1 or abs(stride * self.dt_s - dt_s) > 1e-6:
            raise InputError(f"scene dt_s={dt_s} must be a multiple of the record's {self.dt_s} s")
        if not 0 <= step < self.num_steps:
            raise InputError(f"scene step {step} is outside the record (0..{self.num_steps - 1})")
        n_hist, n_fut = int(round(history_s / dt_s)), int(round(future_s / dt_s))
        tracks = self.tracks()
        states, valid, sizes, kinds = tracks.states, tracks.valid, tracks.sizes, tracks.kinds
        ego = self.ego_id
        if not valid[ego, step]:
            raise InputError(f"the ego is not on the road at recorded step {step}")
        ego_xy = states[ego, step, :2]
        present = np.flatnonzero(valid[:, step])
        others = [a for a in present if a != ego]
        dist = np.array([np.linalg.norm(states[a, step, :2] - ego_xy) for a in others])
        order = [others[i] for i in np.argsort(dist, kind="stable") if dist[i] <= radius_m]
        agents = np.array([ego] + order[: max_agents - 1], dtype=np.int64)

        times = step + stride * np.arange(-n_hist, n_fut + 1)
        inside = (times >= 0) & (times < self.num_steps)
        clipped = np.clip(times, 0, self.num_steps - 1)
        sel_states = states[agents][:, clipped]
        sel_valid = valid[agents][:, clipped] & inside[None, :]
        lane_set = lanes_near(self.road.network, ego_xy, sampling) if lanes else ()
        return Scene(sel_states, sel_valid, sizes[agents], kinds[agents], ego_index=0,
                     current_index=n_hist, dt=dt_s, lanes=lane_set, source=source,
                     time_s=step * self.dt_s, route_xy=self.route_at(step), agent_ids=agents)

    def route_at(self, step: int) -> np.ndarray | None:
        """The ego's route ahead (`route_ahead`) recorded at `step`, None if none was."""
        route = self._routes.get(step)
        if isinstance(route, _RouteLater):
            route = self._routes[step] = route.compute()
        return route


def scene_from_highway_env(env, history_s: float = HISTORY_S, future_s: float = 0.0, *,
                           recorder: TrafficRecorder | None = None, dt_s: float = PLAN_DT_S,
                           radius_m: float = 120.0, max_agents: int = 32,
                           sampling: LaneSampling = LaneSampling()) -> Scene:
    """The scene of a live highway-env env now, in the toolkit's world frame.

    History comes from `recorder` (one that has been recording this env at a rate dividing
    `dt_s`); without one only the present is valid. A positive `future_s` is obtained by letting
    the simulator continue on a deep copy of the road, every vehicle (the ego too) following its
    own behaviour model; the env itself is left untouched.
    """
    base = env.unwrapped
    sim_dt = 1.0 / float(base.config["simulation_frequency"])
    if recorder is None:
        recorder = TrafficRecorder(base.road, base.vehicle, dt_s)
        recorder.record()
        sub_steps = int(round(dt_s / sim_dt))
    else:
        sub_steps = int(round(recorder.dt_s / sim_dt))
        if recorder.num_steps == 0:
            recorder.record()
    now = recorder.num_steps - 1
    if future_s > 0:
        recorder = copy.copy(recorder)
        recorder._rows = list(recorder._rows)
        recorder._last_heading = dict(recorder._last_heading)
        recorder._routes = dict(recorder._routes)
        recorder._latest = dict(recorder._latest)
        road = copy.deepcopy(base.road)
        # The copies stand in for the originals: map each copy to its original's agent id.
        recorder._ids = dict(recorder._ids)
        for orig, twin in zip(list(base.road.vehicles) + list(base.road.objects),
                              list(road.vehicles) + list(road.objects)):
            recorder._ids[id(twin)] = recorder._agent_id(orig)
            recorder._alive = recorder._alive + [twin]  # keep-alive only; ids come from _sizes
        recorder.road = road
        recorder.ego = road.vehicles[list(base.road.vehicles).index(base.vehicle)]
        for _ in range(int(round(future_s / recorder.dt_s))):
            for _ in range(max(1, sub_steps)):
                road.act()
                road.step(sim_dt)
            recorder.record()
    return recorder.scene(now, history_s, future_s, dt_s, radius_m, max_agents, sampling=sampling,
                          source=str(base.spec.id if base.spec else type(base).__name__))
