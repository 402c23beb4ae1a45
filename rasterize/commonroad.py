"""Scenes from recorded traffic in CommonRoad scenario files (NGSIM US-101, I-80, highD, ...).

Files are read with the `commonroad-io` package (releases 2024.3 through 2026.x, through
`rasterize.commonroad_compat`). CommonRoad's world frame is right-handed with x east and y north,
like the toolkit's, so positions and orientations pass through unchanged.

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
  successors, cut by the same goal rule as simulated data (`rasterize.highway.RouteRule`). Where a
  lanelet has several successors (an intersection) the route takes the one the recorded vehicle
  took (`RecordedTraffic.successor_taken`: the successor holding most of its recorded positions;
  the lowest id when its record never reaches one): that is the navigation intent a deployed car
  has, not a position or speed of the recorded future. Where lanelets overlap (inside an
  intersection) the route starts on the one within 45 degrees of the heading that the recorded
  vehicle used most; NGSIM tracks that leave the mapped turning lanelets use one within 3.5 m, and
  with none the route runs straight along the heading (`_lanelet_under`). A lanelet without
  successors ends the route.
- Traffic lights (`LaneletLight`, `lanelet_lights`): every (lanelet, light) pair of the lanelet
  network, at the lanelet's stop line (its `stop_line`, else the segment between the end points of
  its left and right bounds), with the light's cycle. The cycle is periodic, so it continues before
  and beyond the recording. A light forbids passing ("red") in every state but green and inactive:
  amber (yellow) and red-amber count as red. A light without a cycle has no known state: it is
  left out (not drawn, never red) with a one-time warning naming the file and the light.
  `Scene.signals` holds one `Signal` per (lanelet, light) whose stop line lies within the scene's
  extent (`CommonRoadSceneConfig.extent`), with its state every `dt_s` from now to `future_s`.
  Which light governs a vehicle depends on its turn (a light's direction: left, straight, right or
  combinations, `all`); a movement is red when one of the lights governing it is red and none of
  them is green (`movement_red`), so a green right-turn arrow lets a vehicle turn right on red.
- Goal rule at signals (`route_on_lanelets`): while the next signal on the route is red (for the
  route's turn) at the time the ego would reach its stop line (keeping its speed and gaining the
  rule's acceleration up to the limit), the goal point is held `stop_gap_m` (2 m) before the stop
  line, and never so close that the ego's front would be less than 0.5 m from it; once the light
  is green at arrival the goal passes through. A moving ego that cannot stop at the line braking
  3 m/s² (amber caught it) is committed and goes on; a waiting one whose front is past the mapped
  line (NGSIM drivers stop about 2 m past it) is held where it is (`red_light_hold`).

Raster family: recorded highway traffic uses the highway extent (200 m ahead, 40 m behind, 20 m a
side; `rasterize.config.FAMILY_EXTENTS`), so the shipped highway planner reads these scenes as it
reads simulated ones. NGSIM speeds (mostly below 15 m/s) keep the 6 s future well inside it.
Urban recordings (Lankershim) get an extent derived from their own data
(`riskmap.data.collect_commonroad.derive_settings`): less ahead, wide to the sides for turns.
"""

from __future__ import annotations

import logging
import warnings
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rasterize.config import Extent
from rasterize.errors import InputError
from rasterize.geometry import Polyline, drop_repeats
from rasterize.highway import RouteRule
from rasterize.scene import STATE_DIM, AgentKind, Lane, LineType, Scene, Signal
from rasterize.timebase import FUTURE_S, HISTORY_S, PLAN_DT_S

log = logging.getLogger(__name__)

# Obstacle types that drive: they may be demonstrators, and they are VEHICLE agents.
VEHICLE_TYPES = ("car", "truck", "bus", "motorcycle", "taxi", "priorityVehicle")


@dataclass(frozen=True)
class CommonRoadSceneConfig:
    """How a Scene is cut from a recording. Seconds, metres, metres/second."""

    history_s: float = HISTORY_S
    future_s: float = FUTURE_S
    dt_s: float = PLAN_DT_S           # the toolkit's window rate (2 Hz)
    radius_m: float = 120.0           # agents farther than this from the ego are left out
    max_agents: int = 32              # the ego included
    lane_radius_m: float = 260.0      # lanelets whose centre line comes this close are kept
    # The route rule's speed limit when the file gives none: 65 mph, the US-101 / I-80 limit.
    speed_limit_mps: float = 29.06
    route_rule: RouteRule = field(default_factory=RouteRule)
    # Signals whose stop line lies in this ego-centred rectangle are in the scene (the raster's
    # extent); None: those within `lane_radius_m` of the ego.
    extent: Extent | None = None
    # At a red light the goal point is held this far before the stop line (`red_light_hold`).
    stop_gap_m: float = 2.0

    def __post_init__(self) -> None:
        for name in ("history_s", "future_s", "stop_gap_m"):
            if not getattr(self, name) >= 0:
                raise InputError(f"CommonRoadSceneConfig.{name} must be >= 0")
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
        # The XML reader alone (why: rasterize.commonroad_compat), from the one module that
        # knows where each supported commonroad-io release keeps its classes.
        from rasterize.commonroad_compat import XMLFileReader
    except ImportError:
        raise InputError("reading CommonRoad files needs the commonroad-io package (2024.3 to "
                         "2026.x); install it as the README's `riskmap collect --from-commonroad` "
                         "section says") from None
    try:
        # commonroad-io logs a warning per old-style lanelet successor tag ("successorRight ...
        # is of deprecated format"): hundreds per Lankershim file, none of them actionable.
        logging.getLogger(XMLFileReader.__module__).setLevel(logging.ERROR)
        with warnings.catch_warnings():
            # shapely warns (on stderr) about NaN coordinates; they are refused just below
            warnings.simplefilter("ignore", RuntimeWarning)
            scenario, _ = XMLFileReader(str(path)).open()
    except Exception as err:  # noqa: BLE001 - any parse failure is a bad file for the user
        raise InputError(f"CommonRoad file {path} could not be read ({type(err).__name__}: "
                         f"{str(err).splitlines()[0] if str(err) else ''}); pass a valid scenario "
                         "file") from None
    for lanelet in scenario.lanelet_network.lanelets:
        for bound in (lanelet.left_vertices, lanelet.right_vertices, lanelet.center_vertices):
            if not np.isfinite(np.asarray(bound, dtype=float)).all():
                raise InputError(f"CommonRoad file {path}: lanelet {lanelet.lanelet_id} has NaN or inf "
                                 "points; repair its map or leave the file out")
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
    return Polyline(line).nearest(point)[2]


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


# --- traffic lights ------------------------------------------------------------------------------

# Light states that let a vehicle pass; every other state (red, yellow, redYellow) forbids it.
GO_STATES = ("green", "inactive")
TURNS = ("left", "straight", "right")
# CommonRoad's light directions -> the turns they govern.
DIRECTION_TURNS = {
    "right": frozenset({"right"}), "straight": frozenset({"straight"}), "left": frozenset({"left"}),
    "leftStraight": frozenset({"left", "straight"}), "straightRight": frozenset({"straight", "right"}),
    "leftRight": frozenset({"left", "right"}), "all": frozenset(TURNS),
}
_WARNED: set[tuple[str, int]] = set()     # (file, light id) already warned about


@dataclass(frozen=True, eq=False)
class LaneletLight:
    """One traffic light at one lanelet's stop line, with its cycle (module doc).

    stop_line [2, 2] world m; forward [2]: the lanelet's unit driving direction at its stop line;
    turns: the turns the light governs (subset of `TURNS`); states [E] and durations_steps [E]:
    the cycle's elements (CommonRoad colour names, time steps of `dt_s` s); offset_steps: the
    recording step at which the cycle's first element starts (the cycle repeats before and after).
    """

    lanelet_id: int
    light_id: int
    stop_line: np.ndarray
    forward: np.ndarray
    turns: frozenset
    states: tuple[str, ...]
    durations_steps: tuple[int, ...]
    offset_steps: int
    dt_s: float

    def state_at(self, t_s) -> np.ndarray:
        """The light's state (colour name) at times `t_s` (seconds from the recording's step 0),
        as CommonRoad's `TrafficLightCycle.get_state_at_time_step` gives it at that step."""
        steps = np.floor(np.asarray(t_s, dtype=np.float64) / self.dt_s + 1e-6).astype(np.int64)
        ends = np.cumsum(self.durations_steps)
        phase = (steps - self.offset_steps) % ends[-1]
        return np.asarray(self.states, dtype=object)[np.searchsorted(ends, phase, side="right")]

    def red_at(self, t_s) -> np.ndarray:
        """Whether the light forbids passing at times `t_s` (s from the recording's step 0): every
        state but green and inactive, so amber counts as red."""
        state = self.state_at(t_s)
        return ~np.isin(state, GO_STATES)

    def green_at(self, t_s) -> np.ndarray:
        return self.state_at(t_s) == "green"

    def signal(self, now_s: float, times_s: np.ndarray) -> Signal:
        """The `Signal` of this light `times_s` seconds after `now_s`."""
        return Signal(self.stop_line, times_s, self.red_at(now_s + np.asarray(times_s)))


def movement_red(lights: Sequence[LaneletLight], t_s: float) -> bool:
    """Whether passing the stop line is forbidden at `t_s` for a movement governed by `lights`:
    one of them is red and none is green (a green arrow overrides a red ball; inactive lights
    do not govern). No lights: not red."""
    t = np.array([t_s])
    return (any(bool(light.red_at(t)[0]) for light in lights)
            and not any(bool(light.green_at(t)[0]) for light in lights))


def _light_cycle(light) -> tuple[tuple[str, ...], tuple[int, ...], int] | None:
    """(states, durations, offset) of a CommonRoad light's cycle; None when it has no usable one."""
    cycle = getattr(light, "traffic_light_cycle", None)
    elements = list(getattr(cycle, "cycle_elements", None) or [])
    if not elements:
        return None
    states = tuple(str(getattr(e.state, "value", e.state)) for e in elements)
    durations = tuple(int(e.duration) for e in elements)
    if any(d < 0 for d in durations) or sum(durations) <= 0:
        return None
    return states, durations, int(getattr(cycle, "time_offset", 0) or 0)


def _warn_once(name: str, light_id: int, why: str) -> None:
    if (name, light_id) not in _WARNED:
        _WARNED.add((name, light_id))
        log.warning("CommonRoad file %s: traffic light %d %s; its state is unknown, so it is left "
                    "out of the scenes (not drawn, never red)", name, light_id, why)


def _stop_line_of(lanelet) -> np.ndarray:
    """[2, 2]: the lanelet's stop line, or the segment between the end points of its bounds."""
    line = getattr(lanelet, "stop_line", None)
    start, end = getattr(line, "start", None), getattr(line, "end", None)
    if start is not None and end is not None:
        points = np.array([np.asarray(start, float).reshape(-1)[:2], np.asarray(end, float).reshape(-1)[:2]])
        if np.isfinite(points).all() and np.linalg.norm(points[1] - points[0]) > 1e-6:
            return points
    return np.array([np.asarray(lanelet.left_vertices[-1], float)[:2],
                     np.asarray(lanelet.right_vertices[-1], float)[:2]])


def _direction_at(centre: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Unit direction [2] of a centre line at the segment nearest `point`."""
    line = Polyline(centre)
    d = line.segments[line.nearest(point)[0]]
    return d / max(float(np.linalg.norm(d)), 1e-12)


def lanelet_lights(network, dt_s: float, name: str = "") -> tuple[LaneletLight, ...]:
    """Every (lanelet, traffic light) pair of a lanelet network with a known cycle, ordered by
    lanelet and light id. A light without a cycle (or referenced but missing) is left out with a
    one-time warning naming the file (`name`) and the light (module doc)."""
    out = []
    for lanelet in sorted(network.lanelets, key=lambda ll: ll.lanelet_id):
        refs = set(getattr(lanelet, "traffic_lights", None) or ())
        refs |= set(getattr(getattr(lanelet, "stop_line", None), "traffic_light_ref", None) or ())
        if not refs:
            continue
        stop_line = _stop_line_of(lanelet)
        forward = _direction_at(np.asarray(lanelet.center_vertices, float), stop_line.mean(axis=0))
        for light_id in sorted(refs):
            light = network.find_traffic_light_by_id(light_id)
            if light is None:
                _warn_once(name, int(light_id), f"(lanelet {lanelet.lanelet_id}) is not in the file")
                continue
            cycle = _light_cycle(light)
            if cycle is None:
                _warn_once(name, int(light_id), "has no cycle")
                continue
            direction = str(getattr(getattr(light, "direction", None), "value", "all") or "all")
            out.append(LaneletLight(int(lanelet.lanelet_id), int(light_id), stop_line, forward,
                                    DIRECTION_TURNS.get(direction, frozenset(TURNS)), *cycle,
                                    dt_s=float(dt_s)))
    return tuple(out)


def turn_between(network, from_id: int, to_id: int) -> str:
    """The turn ("left", "straight", "right") from lanelet `from_id` into its successor `to_id`:
    as an intersection of the file declares it, else from the heading change along the successor
    (more than 30 degrees: a turn)."""
    for intersection in getattr(network, "intersections", None) or ():
        for incoming in getattr(intersection, "incomings", None) or ():
            if from_id not in set(getattr(incoming, "incoming_lanelets", None) or ()):
                continue
            for turn in TURNS:
                if to_id in set(getattr(incoming, f"outgoing_{turn}", None)
                                or getattr(incoming, f"successors_{turn}", None) or ()):
                    return turn
    a = np.asarray(network.find_lanelet_by_id(from_id).center_vertices, float)
    b = np.asarray(network.find_lanelet_by_id(to_id).center_vertices, float)
    d0, d1 = a[-1] - a[-2], b[-1] - b[-2]
    change = float(np.degrees(np.arctan2(d0[0] * d1[1] - d0[1] * d1[0], float(np.dot(d0, d1)))))
    return "left" if change > 30.0 else "right" if change < -30.0 else "straight"


def governing(lights: Sequence[LaneletLight], turn: str | None) -> list[LaneletLight]:
    """The lights of one stop line that govern a vehicle making `turn` (None: unknown turn, all
    of them)."""
    return [light for light in lights if turn is None or turn in light.turns]


def lights_in_extent(lights: Sequence[LaneletLight], ego_state: np.ndarray, extent: Extent | None,
                     radius_m: float) -> list[LaneletLight]:
    """The lights whose stop line lies (an end or its middle) inside `extent` around the ego
    (ego frame: x ahead, y left), or within `radius_m` of the ego when `extent` is None."""
    out = []
    heading = float(np.arctan2(ego_state[3], ego_state[2]))
    c, s = np.cos(heading), np.sin(heading)
    for light in lights:
        points = np.concatenate([light.stop_line, light.stop_line.mean(axis=0, keepdims=True)])
        rel = points - ego_state[:2]
        if extent is None:
            inside = _distance_to_polyline(ego_state[:2], light.stop_line) <= radius_m
        else:
            x, y = rel[:, 0] * c + rel[:, 1] * s, -rel[:, 0] * s + rel[:, 1] * c
            inside = bool(((x <= extent.front_m) & (x >= -extent.back_m)
                           & (y <= extent.left_m) & (y >= -extent.right_m)).any())
        if inside:
            out.append(light)
    return out


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


# --- the ego's route ahead -------------------------------------------------------------------------

def _heading_cos(lanelet, state: np.ndarray) -> float:
    """Cosine between the vehicle's heading and the lanelet's direction at the nearest segment."""
    centre = np.asarray(lanelet.center_vertices)
    seg = np.argmin(np.linalg.norm(centre[:-1] - state[:2], axis=1))
    d = centre[seg + 1] - centre[seg]
    return float(np.dot(d, state[2:4]) / max(np.linalg.norm(d), 1e-9))


ALIGNED_COS = float(np.cos(np.pi / 4))   # a lanelet within 45 degrees of the heading is driven along
NEAR_LANELET_M = 3.5                     # recorded positions may lie beside the mapped lanelets


def _lanelet_under(network, state: np.ndarray, rank: Callable[[int], float] | None = None):
    """The lanelet the vehicle is on, preferring the one whose direction matches its heading.

    With `rank` (lanelet id -> score: a recorded vehicle's use of each lanelet) only lanelets
    within 45 degrees of the heading count: among those under the vehicle the highest score,
    then the best heading; with none under it, the same among those whose centre line is within
    `NEAR_LANELET_M` (NGSIM tracks inside intersections leave the mapped turning lanelets); with
    none there either, None (off the lanelets). Without `rank`: the best heading under it."""
    ids = network.find_lanelet_by_position([np.asarray(state[:2])])[0]
    if rank is not None:
        under = [network.find_lanelet_by_id(i) for i in ids]
        aligned = [ll for ll in under if _heading_cos(ll, state) > ALIGNED_COS]
        if not aligned:
            aligned = [ll for ll in network.lanelets
                       if _distance_to_polyline(np.asarray(state[:2]), np.asarray(ll.center_vertices))
                       <= NEAR_LANELET_M and _heading_cos(ll, state) > ALIGNED_COS]
        return max(aligned, key=lambda ll: (rank(int(ll.lanelet_id)), _heading_cos(ll, state)),
                   default=None)
    best, best_cos = None, -np.inf
    for lanelet_id in ids:
        lanelet = network.find_lanelet_by_id(lanelet_id)
        cos = _heading_cos(lanelet, state)
        if cos > best_cos:
            best, best_cos = lanelet, cos
    return best


def _centre_line_ahead(network, state: np.ndarray, length_m: float,
                       successor: Callable[[Sequence[int]], int] | None = None,
                       rank: Callable[[int], float] | None = None
                       ) -> tuple[np.ndarray, list[int]] | None:
    """The centre line [K, 2] from the vehicle's projection on its lanelet through the lanelet's
    successors for at least `length_m`, and the ids of the lanelets it runs along, or None off the
    lanelets. `successor` picks one of several successors (default: the lowest id), `rank` the
    lanelet it is on among overlapping ones (`_lanelet_under`); a lanelet without successors ends
    the line."""
    lanelet = _lanelet_under(network, state, rank)
    if lanelet is None:
        return None
    centre = Polyline(np.asarray(lanelet.center_vertices, dtype=np.float64))
    seg, t, _ = centre.nearest(state[:2])
    proj = centre.points[seg] + t * centre.segments[seg]
    points = [proj[None], centre.points[seg + 1:]]
    total = _arc_length(np.concatenate(points))
    ids = [int(lanelet.lanelet_id)]
    while total < length_m and lanelet.successor:
        successors = [int(s) for s in lanelet.successor]
        nxt = min(successors) if successor is None or len(successors) == 1 else int(successor(successors))
        if nxt in ids:
            break
        ids.append(nxt)
        lanelet = network.find_lanelet_by_id(nxt)
        more = np.asarray(lanelet.center_vertices, dtype=np.float64)
        points.append(more)
        total += _arc_length(more)
    return drop_repeats(np.concatenate(points)), ids


def _first_crossing(line: np.ndarray, s_line: np.ndarray, segment: np.ndarray,
                    margin_m: float = 0.5) -> float | None:
    """Arc length along polyline `line` (cumulative lengths `s_line`) where it first crosses
    `segment` [2, 2] (extended by `margin_m` at both ends), or None."""
    p, r = segment[0], segment[1] - segment[0]
    length = float(np.linalg.norm(r))
    if length < 1e-9:
        return None
    u_pad = margin_m / length
    a, d = line[:-1], np.diff(line, axis=0)
    denom = d[:, 0] * r[1] - d[:, 1] * r[0]
    ok = np.abs(denom) > 1e-12
    q = p - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (q[:, 0] * r[1] - q[:, 1] * r[0]) / denom          # along the route segment
        u = (q[:, 0] * d[:, 1] - q[:, 1] * d[:, 0]) / denom    # along the stop line
    hits = np.flatnonzero(ok & (t >= 0) & (t <= 1) & (u >= -u_pad) & (u <= 1 + u_pad))
    if hits.size == 0:
        return None
    k = int(hits[0])
    return float(s_line[k] + t[k] * (s_line[k + 1] - s_line[k]))


def time_to_cover(distance_m: float, speed_mps: float, accel_mps2: float, limit_mps: float) -> float:
    """Seconds to drive `distance_m` from `speed_mps`, gaining `accel_mps2` up to `limit_mps`
    (inf when standing without acceleration)."""
    if distance_m <= 0:
        return 0.0
    v0 = max(speed_mps, 0.0)
    top = max(limit_mps, v0)
    if accel_mps2 <= 0 or v0 >= top:
        return distance_m / v0 if v0 > 0 else float("inf")
    t_top = (top - v0) / accel_mps2
    d_top = v0 * t_top + 0.5 * accel_mps2 * t_top ** 2
    if distance_m <= d_top:
        return float((-v0 + np.sqrt(v0 * v0 + 2.0 * accel_mps2 * distance_m)) / accel_mps2)
    return t_top + (distance_m - d_top) / top


FRONT_MARGIN_M = 0.5     # a held goal keeps the ego's front at least this far before the line
CREEP_MPS = 1.0          # at most this fast, a vehicle past a stop line is waiting, not committed
COMMIT_DECEL_MPS2 = 3.0  # a moving vehicle that needs more than this to stop at the line goes


def red_light_hold(network, line: np.ndarray, s_line: np.ndarray, ids: Sequence[int],
                   lights: Mapping[int, Sequence[LaneletLight]], ego_state: np.ndarray,
                   ego_length_m: float, now_s: float, rule: RouteRule, speed_limit_mps: float,
                   stop_gap_m: float, reach_m: float) -> float | None:
    """Route distance (m from the ego's centre, >= 0) at which the goal is held before a red
    light, or None.

    The signals of the route's lanelets (`ids`, and the lanelet before the first, whose stop line
    the ego may be straddling) are visited in route order while their hold point is within
    `reach_m`. The first stop line that the ego's rear has not passed, whose lights (for the
    route's turn there) are red when the ego's front would reach it, holds the goal point
    `stop_gap_m` before the line, and at least `FRONT_MARGIN_M` farther back than half the ego's
    length, so that an ego at its goal has not put its front across the line (an ego already
    closer than that is held where it is). A moving ego (faster than `CREEP_MPS`) that cannot stop
    its front at the line braking `COMMIT_DECEL_MPS2` is committed: that signal does not hold.
    Recorded drivers wait with their front past the mapped stop line (NGSIM: by about 2 m), so a
    front past the line alone does not commit a slow one."""
    speed = max(float(ego_state[4]), 0.0)
    half = 0.5 * ego_length_m
    # Look behind the ego's centre as far as its rear (and a metre more).
    back = half + 1.0
    line = np.concatenate([ego_state[None, :2] - back * ego_state[2:4], line])
    s_line = np.concatenate([[-back], s_line])
    first = network.find_lanelet_by_id(ids[0]) if ids else None
    visits = [(int(p), ids[0]) for p in (getattr(first, "predecessor", None) or ()) if int(p) in lights]
    visits += [(lanelet_id, ids[k + 1] if k + 1 < len(ids) else None) for k, lanelet_id in enumerate(ids)]
    for lanelet_id, nxt in visits:
        if lanelet_id not in lights:
            continue
        turn = turn_between(network, lanelet_id, nxt) if nxt is not None else None
        governed = governing(lights[lanelet_id], turn)
        if not governed:
            continue
        s_stop = _first_crossing(line, s_line, governed[0].stop_line)
        if s_stop is None:
            continue
        if s_stop <= -half:
            continue                                    # the rear is past: behind the ego
        front_to_line = s_stop - half
        if speed > CREEP_MPS and front_to_line < speed * speed / (2.0 * COMMIT_DECEL_MPS2):
            continue                                    # cannot stop comfortably: committed
        hold = s_stop - max(stop_gap_m, half + FRONT_MARGIN_M)
        if hold > reach_m:
            break
        arrival = now_s + time_to_cover(max(front_to_line, 0.0), speed, rule.accel_mps2,
                                        speed_limit_mps)
        if np.isfinite(arrival) and movement_red(governed, arrival):
            return max(0.0, hold)
    return None


def route_on_lanelets(network, ego_state: np.ndarray, ego_length_m: float, others: np.ndarray,
                      other_lengths_m: np.ndarray, rule: RouteRule | None = None,
                      speed_limit_mps: float = 29.06, *,
                      successor: Callable[[Sequence[int]], int] | None = None,
                      rank: Callable[[int], float] | None = None,
                      lights: Mapping[int, Sequence[LaneletLight]] | None = None,
                      now_s: float = 0.0, stop_gap_m: float = 2.0) -> np.ndarray:
    """[rule.points, 2] world points from the ego along its lane to its goal (the route rule).

    Free distance = min(limit × T, v × T + a T² / 2); a leader within the rule's half-width of the
    route caps it at the leader's position after T less a standstill gap and a time headway; a red
    light ahead (`lights` by lanelet id, states at `now_s` s from the recording's step 0) holds it
    before its stop line (`red_light_hold`). `successor` picks the way through intersections
    (default: the lowest successor id) and `rank` the lanelet the ego is on where lanelets
    overlap (default: the best heading). Off the lanelets the route runs straight ahead along the
    ego's heading.
    """
    rule = rule or RouteRule()
    t = rule.horizon_s
    speed = max(float(ego_state[4]), 0.0)
    free = min(speed_limit_mps * t, speed * t + 0.5 * rule.accel_mps2 * t * t)
    reach = free + 40.0                                   # look for leaders a little further
    ahead = _centre_line_ahead(network, ego_state, reach, successor, rank)
    line, ids = ahead if ahead is not None else (None, [])
    if line is None or len(line) < 2:
        line, ids = np.stack([ego_state[:2], ego_state[:2] + reach * ego_state[2:4]]), []
    line = np.concatenate([ego_state[None, :2], line[1:]]) if len(line) > 1 else line
    route = Polyline(line)
    s_line = route.arc
    along = np.arange(0.0, reach + rule.sample_m, rule.sample_m)
    dense = route.point_at(along)
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
    if lights and ids:
        held = red_light_hold(network, line, s_line, ids, lights, ego_state, ego_length_m, now_s,
                              rule, speed_limit_mps, stop_gap_m, reach_m=free)
        if held is not None:
            distance = min(distance, held)
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
