"""Scenes from recorded traffic in CommonRoad scenario files (NGSIM US-101, I-80, highD, ...).

Files are read with the `commonroad-io` package. CommonRoad's world frame is right-handed with x
east and y north, like the toolkit's, so positions and orientations pass through unchanged.

- Lanelets become `Lane`s: centre line and left/right bounds as the file gives them (CommonRoad
  samples both bounds at the same number of vertices, so they line up point by point). Line
  types come from the lanelets' line markings; where the file has none (the 2018b format, or
  `unknown`), a bound shared with a same-direction neighbour is dashed and any other bound is a
  solid road edge, as highway-env paints its roads.
- Dynamic obstacles become agents with their rectangle (or a box around any other shape). Their
  recorded states (at the file's `dt`) are resampled by linear interpolation (heading by its
  unwrapped angle) onto the toolkit's grid of times; times outside a vehicle's record are
  invalid, which is how vehicles entering and leaving the recording show up.
- The ego's route (`Scene.route_xy`) follows the centre line of the lanelet the ego is on and its
  successors, cut by the same goal rule as simulated data (`rasterize.highway.RouteRule`): only
  present information, never the recorded future.

Raster family: recorded highway traffic uses the highway extent (200 m ahead, 40 m behind, 20 m a
side; `rasterize.config.FAMILY_EXTENTS`), so the shipped highway planner reads these scenes as it
reads simulated ones. NGSIM speeds (mostly below 15 m/s) keep the 6 s future well inside it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from rasterize.highway import RouteRule
from rasterize.scene import STATE_DIM, AgentKind, Lane, LineType, Scene

# Obstacle types that drive: they may be demonstrators, and they are VEHICLE agents.
VEHICLE_TYPES = ("car", "truck", "bus", "motorcycle", "taxi", "priorityVehicle")


@dataclass(frozen=True)
class CommonRoadSceneConfig:
    """How a Scene is cut from a recording. Seconds, metres, metres/second."""

    history_s: float = 2.0
    future_s: float = 6.0
    dt_s: float = 0.5                 # the toolkit's window rate (2 Hz)
    radius_m: float = 120.0           # agents farther than this from the ego are left out
    max_agents: int = 32              # the ego included
    lane_radius_m: float = 260.0      # lanelets whose centre line comes this close are kept
    # The route rule's speed limit when the file gives none: 65 mph, the US-101 / I-80 limit.
    speed_limit_mps: float = 29.06
    route_rule: RouteRule = field(default_factory=RouteRule)

    def __post_init__(self) -> None:
        for name in ("history_s", "future_s"):
            if not getattr(self, name) >= 0:
                raise InputError(f"CommonRoadSceneConfig.{name} must be >= 0 seconds")
        for name in ("dt_s", "radius_m", "lane_radius_m", "speed_limit_mps"):
            if not getattr(self, name) > 0:
                raise InputError(f"CommonRoadSceneConfig.{name} must be positive")
        if self.max_agents < 1:
            raise InputError("CommonRoadSceneConfig.max_agents must be at least 1")

    @property
    def history_steps(self) -> int:
        return round(self.history_s / self.dt_s)

    @property
    def future_steps(self) -> int:
        return round(self.future_s / self.dt_s)


def load_scenario(path: str | Path):
    """The `commonroad.scenario.scenario.Scenario` in an XML file (InputError if unreadable)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"CommonRoad file {path} does not exist; pass an existing scenario .xml")
    try:
        # The XML reader alone: the package's protobuf reader needs an old protobuf runtime,
        # which conflicts with tensorboard's, and XML is the format recordings come in.
        from commonroad.common.reader.file_reader_xml import XMLFileReader
    except ImportError:
        raise InputError("reading CommonRoad files needs the commonroad-io package; install it "
                         "as the README's 'Recorded traffic' section says") from None
    try:
        scenario, _ = XMLFileReader(str(path)).open()
    except Exception as err:  # noqa: BLE001 - any parse failure is a bad file for the user
        raise InputError(f"CommonRoad file {path} could not be read ({type(err).__name__}: "
                         f"{str(err).splitlines()[0] if str(err) else ''}); pass a valid scenario "
                         "file") from None
    return scenario


# --- lanes ---------------------------------------------------------------------------------------

def _line_type(marking, has_same_direction_neighbour: bool) -> LineType:
    value = getattr(marking, "value", str(marking))
    if value in ("dashed", "broad_dashed", "dashed_dashed"):
        return LineType.DASHED
    if value in ("solid_solid", "broad_solid"):
        return LineType.SOLID_THICK
    if value in ("solid", "solid_dashed", "dashed_solid", "curb", "lowered_curb"):
        return LineType.SOLID
    if value == "no_marking":
        return LineType.NONE
    return LineType.DASHED if has_same_direction_neighbour else LineType.SOLID


def _arc_length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _distance_to_polyline(point: np.ndarray, line: np.ndarray) -> float:
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(((point - a) * ab).sum(axis=1) / np.maximum((ab * ab).sum(axis=1), 1e-12), 0, 1)
    return float(np.linalg.norm(a + t[:, None] * ab - point, axis=1).min())


def _start_arc_lengths(network) -> dict[int, float]:
    """Arc length from the start of each lanelet's chain of first predecessors, so that dashes
    keep their phase across consecutive lanelets."""
    by_id = {ll.lanelet_id: ll for ll in network.lanelets}
    memo: dict[int, float] = {}

    def start(lanelet_id: int, depth: int = 0) -> float:
        if lanelet_id in memo:
            return memo[lanelet_id]
        preds = [p for p in by_id[lanelet_id].predecessor if p in by_id]
        value = 0.0
        if preds and depth < 200:   # depth guards against cycles in odd maps
            first = min(preds)
            value = start(first, depth + 1) + _arc_length(by_id[first].center_vertices)
        memo[lanelet_id] = value
        return value

    return {lanelet_id: start(lanelet_id) for lanelet_id in sorted(by_id)}


def lanes_from_lanelets(network, centre_world: np.ndarray | None = None,
                        radius_m: float = np.inf) -> tuple[Lane, ...]:
    """Every lanelet of a CommonRoad `LaneletNetwork` within `radius_m` of a point, as `Lane`s,
    in increasing lanelet id."""
    starts = _start_arc_lengths(network)
    lanes = []
    for lanelet in sorted(network.lanelets, key=lambda ll: ll.lanelet_id):
        centre = np.asarray(lanelet.center_vertices, dtype=np.float64)
        if centre_world is not None and _distance_to_polyline(np.asarray(centre_world), centre) > radius_m:
            continue
        left = np.asarray(lanelet.left_vertices, dtype=np.float64)
        right = np.asarray(lanelet.right_vertices, dtype=np.float64)
        width = float(np.linalg.norm(left - right, axis=1).mean())
        left_line = _line_type(lanelet.line_marking_left_vertices,
                               lanelet.adj_left is not None and bool(lanelet.adj_left_same_direction))
        right_line = _line_type(lanelet.line_marking_right_vertices,
                                lanelet.adj_right is not None and bool(lanelet.adj_right_same_direction))
        lanes.append(Lane(centre, left, right, left_line, right_line, width,
                          starts[lanelet.lanelet_id]))
    return tuple(lanes)


# --- recorded traffic ----------------------------------------------------------------------------

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
    """

    def __init__(self, scenario, name: str = "", smoothing_s: float = 0.0):
        self.scenario, self.name = scenario, name or str(getattr(scenario, "scenario_id", ""))
        self.dt_s = float(scenario.dt)
        self.smoothing_s = float(smoothing_s)
        self.rejected: dict[int, str] = {}
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
        route = route_on_lanelets(network, self.states[ego, time_index], self.sizes[ego, 0],
                                  self.states[agents[1:], time_index], self.sizes[agents[1:], 0],
                                  config.route_rule, config.speed_limit_mps)
        return Scene(states, valid, self.sizes[agents], self.kinds[agents], ego_index=0,
                     current_index=config.history_steps, dt=config.dt_s, lanes=lanes,
                     source=f"commonroad:{self.name}", time_s=now_s, route_xy=route)


# --- the ego's route ahead -------------------------------------------------------------------------

def _lanelet_under(network, state: np.ndarray):
    """The lanelet the vehicle is on, preferring the one whose direction matches its heading."""
    ids = network.find_lanelet_by_position([np.asarray(state[:2])])[0]
    best, best_cos = None, -np.inf
    for lanelet_id in ids:
        lanelet = network.find_lanelet_by_id(lanelet_id)
        centre = np.asarray(lanelet.center_vertices)
        seg = np.argmin(np.linalg.norm(centre[:-1] - state[:2], axis=1))
        d = centre[seg + 1] - centre[seg]
        cos = float(np.dot(d, state[2:4]) / max(np.linalg.norm(d), 1e-9))
        if cos > best_cos:
            best, best_cos = lanelet, cos
    return best


def _centre_line_ahead(network, state: np.ndarray, length_m: float) -> np.ndarray | None:
    """The centre line [K, 2] from the vehicle's projection on its lanelet through the lanelet's
    successors (lowest id first) for at least `length_m`, or None off the lanelets."""
    lanelet = _lanelet_under(network, state)
    if lanelet is None:
        return None
    centre = np.asarray(lanelet.center_vertices, dtype=np.float64)
    a, b = centre[:-1], centre[1:]
    ab = b - a
    t = np.clip(((state[:2] - a) * ab).sum(axis=1) / np.maximum((ab * ab).sum(axis=1), 1e-12), 0, 1)
    proj = a + t[:, None] * ab
    seg = int(np.argmin(np.linalg.norm(proj - state[:2], axis=1)))
    points = [proj[seg][None], centre[seg + 1:]]
    total = _arc_length(np.concatenate(points))
    seen = {lanelet.lanelet_id}
    while total < length_m and lanelet.successor:
        nxt = min(s for s in lanelet.successor)
        if nxt in seen:
            break
        seen.add(nxt)
        lanelet = network.find_lanelet_by_id(nxt)
        more = np.asarray(lanelet.center_vertices, dtype=np.float64)
        points.append(more)
        total += _arc_length(more)
    line = np.concatenate(points)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(line, axis=0), axis=1) > 1e-6])
    return line[keep]


def route_on_lanelets(network, ego_state: np.ndarray, ego_length_m: float, others: np.ndarray,
                      other_lengths_m: np.ndarray, rule: RouteRule | None = None,
                      speed_limit_mps: float = 29.06) -> np.ndarray:
    """[rule.points, 2] world points from the ego along its lane to its goal (the route rule).

    Free distance = min(limit × T, v × T + a T² / 2); a leader within the rule's half-width of the
    route caps it at the leader's position after T less a standstill gap and a time headway.
    Off the lanelets the route runs straight ahead along the ego's heading.
    """
    rule = rule or RouteRule()
    t = rule.horizon_s
    speed = max(float(ego_state[4]), 0.0)
    free = min(speed_limit_mps * t, speed * t + 0.5 * rule.accel_mps2 * t * t)
    reach = free + 40.0                                   # look for leaders a little further
    line = _centre_line_ahead(network, ego_state, reach)
    if line is None or len(line) < 2:
        line = np.stack([ego_state[:2], ego_state[:2] + reach * ego_state[2:4]])
    line = np.concatenate([ego_state[None, :2], line[1:]]) if len(line) > 1 else line
    s_line = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    along = np.arange(0.0, reach + rule.sample_m, rule.sample_m)
    dense = np.stack([np.interp(along, s_line, line[:, 0]), np.interp(along, s_line, line[:, 1])], 1)
    distance = free
    for other, length in zip(np.asarray(others).reshape(-1, STATE_DIM), np.asarray(other_lengths_m)):
        if np.linalg.norm(other[:2] - ego_state[:2]) > reach + 10.0:
            continue
        offsets = np.linalg.norm(dense - other[:2], axis=1)
        j = int(np.argmin(offsets))
        if j == 0 or offsets[j] > rule.lane_half_width_m:
            continue                                      # beside or behind, or off the route
        direction = dense[min(j + 1, len(dense) - 1)] - dense[max(j - 1, 0)]
        direction /= max(np.linalg.norm(direction), 1e-9)
        v_lead = max(0.0, float(np.dot(other[4] * other[2:4], direction)))
        gap = along[j] - 0.5 * (ego_length_m + float(length))
        cap = gap + v_lead * t - (rule.standstill_gap_m + v_lead * rule.headway_s)
        distance = min(distance, max(0.0, cap))
    ds = np.linspace(0.0, distance, rule.points)
    return np.stack([np.interp(ds, along, dense[:, 0]), np.interp(ds, along, dense[:, 1])], axis=1)


# --- the public entry point ------------------------------------------------------------------------

def scene_from_commonroad(path_or_scenario, ego_id: int, time_index: int,
                          config: CommonRoadSceneConfig = CommonRoadSceneConfig()) -> Scene:
    """The Scene of recorded vehicle `ego_id` at the file's time step `time_index`.

    `path_or_scenario`: a CommonRoad .xml path, a loaded `Scenario`, or a `RecordedTraffic`
    (reuse one when cutting many scenes from a file). History and future are resampled to
    `config.dt_s`; agents without a record at a time are invalid there.
    """
    if isinstance(path_or_scenario, RecordedTraffic):
        traffic = path_or_scenario
    elif isinstance(path_or_scenario, (str, Path)):
        traffic = RecordedTraffic(load_scenario(path_or_scenario), Path(path_or_scenario).stem)
    else:
        traffic = RecordedTraffic(path_or_scenario)
    if not isinstance(time_index, (int, np.integer)):
        raise InputError(f"time index {time_index!r} must be an integer step of the recording")
    return traffic.scene(traffic.index_of(ego_id), int(time_index), config)
