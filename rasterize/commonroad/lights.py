"""Traffic lights: every (lanelet, light) pair of a lanelet network with its cycle
(`LaneletLight`, `lanelet_lights`), and which of them govern a movement (package doc)."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rasterize.commonroad.lanes import _distance_to_polyline
from rasterize.config import Extent
from rasterize.geometry import Polyline
from rasterize.scene import Signal

log = logging.getLogger(__name__)

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
