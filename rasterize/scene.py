"""The `Scene`: one moment of one episode, with the history and (when known) future around it.

Shapes, stated once:
    N agents, T time steps, P points per lane polyline.
    states  [N, T, 6]  (x, y, heading_x, heading_y, speed, yaw_rate): world metres, unit heading
                       vector, metres/second, radians/second.
    valid   [N, T]     True where the agent exists at that time.
    sizes   [N, 2]     (length, width) in metres.
    kinds   [N]        :class:`AgentKind` codes.

The world frame is right-handed (x east, y north). Simulator adapters convert into it.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace

import numpy as np

from rasterize.errors import InputError

STATE_DIM = 6
X, Y, HX, HY, SPEED, YAW_RATE = range(STATE_DIM)


class AgentKind(enum.IntEnum):
    VEHICLE = 0
    OBSTACLE = 1


class LineType(enum.IntEnum):
    """Painted line on one side of a lane (same codes as highway-env's LineType)."""

    NONE = 0
    DASHED = 1
    SOLID = 2
    SOLID_THICK = 3


@dataclass(frozen=True, eq=False)
class Lane:
    """A lane as polylines sampled at the same arc lengths, world metres.

    centre, left, right: [P, 2]; left/right are the boundaries to the left/right of the driving
    direction. start_s is the arc length (m) of the first point along the simulator's lane, so
    that dashes stay put when a lane is cropped differently from scene to scene.
    """

    centre: np.ndarray
    left: np.ndarray
    right: np.ndarray
    left_line: LineType = LineType.DASHED
    right_line: LineType = LineType.DASHED
    width_m: float = 4.0
    start_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("centre", "left", "right"):
            arr = np.asarray(getattr(self, name), dtype=np.float64)
            if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 2:
                raise InputError(f"Lane.{name} must have shape [P>=2, 2], got {arr.shape}")
            if not np.isfinite(arr).all():
                raise InputError(f"Lane.{name} has non-finite points; drop or repair the lane")
            object.__setattr__(self, name, arr)
        if not (self.centre.shape == self.left.shape == self.right.shape):
            raise InputError(
                "Lane polylines must be sampled at the same arc lengths: "
                f"centre {self.centre.shape}, left {self.left.shape}, right {self.right.shape}"
            )
        object.__setattr__(self, "left_line", LineType(int(self.left_line)))
        object.__setattr__(self, "right_line", LineType(int(self.right_line)))

    def polygon(self) -> np.ndarray:
        """The lane's area as one closed polygon [2P, 2]."""
        return np.concatenate([self.left, self.right[::-1]], axis=0)


@dataclass(frozen=True, eq=False)
class Signal:
    """A traffic light at one lane's stop line, and its state over the next seconds.

    stop_line [2, 2]: the line's two ends, world metres (across the lane, where vehicles stop).
    times_s [K]: seconds from the scene's current time (times_s[0] = 0, increasing).
    red [K] bool: the light forbids passing the stop line at that time (red, or amber treated as
    red: CommonRoad cycles give red / red-yellow / yellow / green; all but green forbid).
    """

    stop_line: np.ndarray
    times_s: np.ndarray
    red: np.ndarray

    def __post_init__(self) -> None:
        line = np.asarray(self.stop_line, dtype=np.float64)
        times = np.asarray(self.times_s, dtype=np.float64)
        red = np.asarray(self.red, dtype=bool)
        if line.shape != (2, 2) or not np.isfinite(line).all():
            raise InputError(f"Signal.stop_line must be finite [2, 2] metres, got {line.shape}")
        if times.ndim != 1 or len(times) < 1 or red.shape != times.shape \
                or not np.isfinite(times).all() or (np.diff(times) <= 0).any():
            raise InputError("Signal.times_s must be increasing finite seconds [K>=1] and "
                             f"Signal.red bool [K]; got {times.shape} and {red.shape}")
        object.__setattr__(self, "stop_line", line)
        object.__setattr__(self, "times_s", times)
        object.__setattr__(self, "red", red)

    def red_at(self, t_s: float) -> bool:
        """Whether the light is red `t_s` seconds from now (the last known state beyond K)."""
        return bool(self.red[max(0, int(np.searchsorted(self.times_s, t_s, side="right")) - 1)])


class AgentsOverSteps:
    """`num_agents` and `num_steps` of a holder of `states` [A, S, ...] (a scene, tracks)."""

    @property
    def num_agents(self) -> int:
        return self.states.shape[0]

    @property
    def num_steps(self) -> int:
        return self.states.shape[1]


@dataclass(frozen=True, eq=False)
class Scene(AgentsOverSteps):
    """One moment of one episode (see the module docstring for shapes and units)."""

    states: np.ndarray
    valid: np.ndarray
    sizes: np.ndarray
    kinds: np.ndarray
    ego_index: int
    current_index: int
    dt: float
    lanes: tuple[Lane, ...] = field(default_factory=tuple)
    source: str = ""
    time_s: float = 0.0
    # The ego's route ahead [K, 2] (world m), from the ego to the point the route rule picks as
    # its goal (`rasterize.highway.route_ahead`); None when unknown.
    route_xy: np.ndarray | None = None
    # Traffic lights at stop lines, with their state over the next seconds (recordings with
    # signals; empty elsewhere).
    signals: tuple[Signal, ...] = field(default_factory=tuple)
    # The world's own id of each agent row [N] (int), the same for one vehicle in every scene of
    # an episode (a recorder's agent id, a recording's obstacle id); None where the source keeps
    # none. Planners that must follow agents across replans read it (a CommonRoad planner's
    # obstacle ids, `riskmap.planner.commonroad_planner`); nothing else does.
    agent_ids: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.route_xy is not None:
            route = np.asarray(self.route_xy, dtype=np.float64)
            if route.ndim != 2 or route.shape[1] != 2 or len(route) < 1 or not np.isfinite(route).all():
                raise InputError(f"Scene.route_xy must be finite [K>=1, 2], got {route.shape}")
            object.__setattr__(self, "route_xy", route)
        states = np.asarray(self.states, dtype=np.float64)
        valid = np.asarray(self.valid, dtype=bool)
        sizes = np.asarray(self.sizes, dtype=np.float64)
        kinds = np.asarray(self.kinds, dtype=np.int8)
        if states.ndim != 3 or states.shape[2] != STATE_DIM:
            raise InputError(f"Scene.states must have shape [N, T, {STATE_DIM}], got {states.shape}")
        n, t, _ = states.shape
        if valid.shape != (n, t):
            raise InputError(f"Scene.valid must have shape {(n, t)}, got {valid.shape}")
        if sizes.shape != (n, 2):
            raise InputError(f"Scene.sizes must have shape {(n, 2)}, got {sizes.shape}")
        if kinds.shape != (n,):
            raise InputError(f"Scene.kinds must have shape {(n,)}, got {kinds.shape}")
        if not 0 <= self.ego_index < n:
            raise InputError(f"Scene.ego_index {self.ego_index} is outside 0..{n - 1}")
        if not 0 <= self.current_index < t:
            raise InputError(f"Scene.current_index {self.current_index} is outside 0..{t - 1}")
        if not self.dt > 0:
            raise InputError(f"Scene.dt must be positive seconds, got {self.dt}")
        if not valid[self.ego_index, self.current_index]:
            raise InputError("Scene: the ego has no valid state at the current time index")
        bad = valid & ~np.isfinite(states).all(axis=2)
        if bad.any():
            agent, step = np.argwhere(bad)[0]
            raise InputError(
                f"Scene has non-finite (NaN/inf) states for agent {agent} at time index {step}; "
                "mark such states invalid or repair the recording"
            )
        if valid.any() and not (np.isfinite(sizes[valid.any(axis=1)]).all()
                                and (sizes[valid.any(axis=1)] > 0).all()):
            raise InputError("Scene.sizes must be positive finite metres for every present agent")
        # Invalid entries carry no meaning; zero them so that they never leak NaN downstream.
        states = np.where(valid[..., None], states, 0.0)
        object.__setattr__(self, "states", states)
        object.__setattr__(self, "valid", valid)
        object.__setattr__(self, "sizes", sizes)
        object.__setattr__(self, "kinds", kinds)
        object.__setattr__(self, "lanes", tuple(self.lanes))
        object.__setattr__(self, "signals", tuple(self.signals))
        if self.agent_ids is not None:
            ids = np.asarray(self.agent_ids)
            if ids.shape != (n,) or not np.issubdtype(ids.dtype, np.integer):
                raise InputError(f"Scene.agent_ids must be integers [{n}], got {ids.dtype} {ids.shape}")
            object.__setattr__(self, "agent_ids", ids.astype(np.int64))

    @property
    def num_future_steps(self) -> int:
        return self.num_steps - self.current_index - 1

    def past(self) -> Scene:
        """The scene without its future: what a planner may see."""
        end = self.current_index + 1
        return replace(self, states=self.states[:, :end], valid=self.valid[:, :end])

    def rotated(self, angle: float) -> Scene:
        """The same scene with the whole world rotated by `angle` (rad) about the world origin."""
        c, s = np.cos(angle), np.sin(angle)
        rot_t = np.array([[c, s], [-s, c]])  # transposed rotation, for row vectors
        states = self.states.copy()
        states[..., 0:2] = states[..., 0:2] @ rot_t
        states[..., 2:4] = states[..., 2:4] @ rot_t
        lanes = tuple(replace(lane, centre=lane.centre @ rot_t, left=lane.left @ rot_t,
                              right=lane.right @ rot_t) for lane in self.lanes)
        route = None if self.route_xy is None else self.route_xy @ rot_t
        signals = tuple(replace(sig, stop_line=sig.stop_line @ rot_t) for sig in self.signals)
        return replace(self, states=states, lanes=lanes, route_xy=route, signals=signals)

    def with_ego_perturbed(self, heading_rad: float, lateral_m: float) -> Scene:
        """The scene with the ego now turned by `heading_rad` and shifted `lateral_m` to its left.

        Only the ego's current state changes: its history and recorded future stay, so a
        demonstration from the perturbed pose shows how to get back onto the recorded path.
        Training on such scenes teaches recovery from the drift a closed loop produces.
        """
        states = self.states.copy()
        ego, now = self.ego_index, self.current_index
        hx, hy = states[ego, now, 2:4]
        c, s = np.cos(heading_rad), np.sin(heading_rad)
        states[ego, now, 0:2] += lateral_m * np.array([-hy, hx])
        states[ego, now, 2:4] = [c * hx - s * hy, s * hx + c * hy]
        return replace(self, states=states)

    def ego_state(self) -> np.ndarray:
        """The ego's current state [6]."""
        return self.states[self.ego_index, self.current_index]

    def ego_future_xy(self) -> np.ndarray:
        """The ego's recorded future positions [T_future, 2], world metres (may be empty)."""
        future = slice(self.current_index + 1, None)
        if not self.valid[self.ego_index, future].all():
            raise InputError("Scene: the ego's future is not fully recorded")
        return self.states[self.ego_index, future, :2]
