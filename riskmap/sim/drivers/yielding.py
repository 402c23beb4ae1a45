"""A teacher that yields: IDM/MOBIL plus gap acceptance at conflict zones (`yielding` SPEC).

highway-env's IDM ego follows the car ahead on its own lane but does not look at crossing
traffic, so at intersection-v0 it drives into cars that cross its path (14.5% of episodes), and
a planner that imitates it learns to do the same. This driver adds what a human does at an
unsignalised junction: before each point where its path meets another vehicle's, it compares
when each of them will be there and waits at a safe distance unless the gap is large enough.

Per step, for every other vehicle:
  1. both paths ahead, along the lanes of their routes (`_route_path`, cached lane polylines);
  2. the first conflict: the first point of the ego's path within `conflict_width_m` of the
     other's path (paths that start together are car following, left to IDM);
  3. when each occupies it: the other at its current speed (it may stop, but a teacher must not
     count on that); the ego accelerating from its current speed at `go_accel_mps2` to its
     desired speed;
  4. gap acceptance: the ego goes if it clears the conflict at least `critical_gap_s` before the
     other arrives, or arrives at least `critical_gap_s` after the other has left; otherwise it
     stops `stop_margin_m` before the conflict (IDM towards a standing obstacle there), unless
     it can no longer stop comfortably before it (then it keeps going and clears).
The critical gap is drawn per episode like the other driver parameters (`YieldingDriver`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from riskmap.sim.loop.plan import HumanDriver


@dataclass(frozen=True)
class GapAcceptance:
    """Gap-acceptance parameters of the yielding teacher (seconds, metres, m/s²)."""

    critical_gap_s: tuple[float, float] = (1.0, 2.0)   # per-episode draw, uniform
    go_accel_mps2: float = 1.5          # the acceleration the ego assumes for itself when it goes
    conflict_width_m: float = 2.6       # paths closer than this conflict (two cars ~2 m wide)
    look_ahead_m: float = 45.0          # the ego's path considered
    look_ahead_s: float = 8.0           # the other's path considered: this long at its speed
    stop_margin_m: float = 1.5          # stop this far before the other's path
    comfort_brake_mps2: float = 4.5     # beyond this the ego is committed and clears instead
    min_speed_mps: float = 0.3          # an other vehicle slower than this is treated as waiting
    sample_m: float = 1.0               # path sampling


def _lane_polyline(network, lane_index, step_m: float, cache: dict) -> np.ndarray:
    """Centre points [P, 2] of a lane every `step_m` from its start to its end (cached)."""
    key = (lane_index, step_m)
    if key not in cache:
        lane = network.get_lane(lane_index)
        s = np.append(np.arange(0.0, lane.length, step_m), lane.length)
        cache[key] = np.array([lane.position(x, 0.0) for x in s])
    return cache[key]


def _lane_sequence(vehicle, max_lanes: int = 4) -> list:
    """The vehicle's current lane and the lanes of its route after it."""
    current = vehicle.lane_index
    lanes = [current]
    route = list(vehicle.route or [])
    for _ in range(max_lanes - 1):
        nxt = next((r for r in route if r[0] == lanes[-1][1] and r[:2] != lanes[-1][:2]), None)
        if nxt is None:
            break
        lanes.append((nxt[0], nxt[1], nxt[2] if nxt[2] is not None else 0))
    return lanes


def _route_path(vehicle, length_m: float, params: GapAcceptance, cache: dict
                ) -> tuple[np.ndarray, np.ndarray]:
    """Points [P, 2] along the vehicle's route from its rear to `length_m` ahead of its centre,
    and their arc length [P] from the vehicle's centre (negative behind it)."""
    network = vehicle.road.network
    lanes = _lane_sequence(vehicle)
    s_on_lane = float(vehicle.lane.local_coordinates(vehicle.position)[0])
    pieces, offsets, covered = [], [], -s_on_lane
    for index in lanes:
        poly = _lane_polyline(network, index, params.sample_m, cache)
        arc = covered + np.linspace(0.0, network.get_lane(index).length, len(poly))
        pieces.append(poly)
        offsets.append(arc)
        covered = arc[-1]
        if covered >= length_m:
            break
    points, arc = np.concatenate(pieces), np.concatenate(offsets)
    if covered < length_m:  # the route ends: continue straight along the last heading
        direction = points[-1] - points[-2]
        direction /= max(np.linalg.norm(direction), 1e-9)
        extra = np.arange(params.sample_m, length_m - covered + params.sample_m, params.sample_m)
        points = np.concatenate([points, points[-1] + extra[:, None] * direction])
        arc = np.concatenate([arc, covered + extra])
    keep = (arc >= -vehicle.LENGTH / 2) & (arc <= length_m)
    return points[keep], arc[keep]


def _time_to_cover(distance_m: float, speed: float, accel: float, top_speed: float) -> float:
    """Seconds to drive `distance_m` from `speed`, accelerating at `accel` up to `top_speed`."""
    if distance_m <= 0:
        return 0.0
    speed = max(speed, 0.0)
    top_speed = max(top_speed, speed, 0.1)
    t_top = (top_speed - speed) / accel
    d_top = speed * t_top + 0.5 * accel * t_top ** 2
    if distance_m <= d_top:
        return float((-speed + np.sqrt(speed ** 2 + 2 * accel * distance_m)) / accel)
    return float(t_top + (distance_m - d_top) / top_speed)


def conflict_stop_distance(ego, others, params: GapAcceptance, critical_gap_s: float,
                           cache: dict) -> float | None:
    """Metres ahead of the ego's centre where it must stop to give way, or None to go on."""
    ego_points, ego_arc = _route_path(ego, params.look_ahead_m, params, cache)
    ahead = ego_arc > ego.LENGTH / 2          # conflicts beside or behind the ego are not its to solve
    ego_points, ego_arc = ego_points[ahead], ego_arc[ahead]
    if len(ego_arc) == 0:
        return None
    top_speed = max(float(getattr(ego, "target_speed", ego.speed)), 1.0)
    stop_at = None
    for other in others:
        if other is ego or np.linalg.norm(other.position - ego.position) > params.look_ahead_m + 60:
            continue
        if other.lane_index[:2] == ego.lane_index[:2]:
            continue  # same lane: car following, IDM's job
        speed = float(other.speed)
        other_points, other_arc = _route_path(
            other, max(speed * params.look_ahead_s, 2 * other.LENGTH), params, cache)
        d = np.linalg.norm(ego_points[:, None, :] - other_points[None, :, :], axis=2)
        close = d < params.conflict_width_m
        if not close.any():
            continue
        i = int(np.flatnonzero(close.any(axis=1))[0])          # first conflict on the ego's path
        if close[0].any() and i == 0 and (other_arc[close[0]] < 0).all():
            continue  # the other's rear is where the ego's path starts: it is ahead, leaving
        s_ego = float(ego_arc[i])
        s_other = float(other_arc[close[i]].min())
        half = 0.5 * params.conflict_width_m
        # Occupation windows of the conflict point (front reaches it .. rear leaves it).
        e_in = _time_to_cover(s_ego - ego.LENGTH / 2 - half, ego.speed, params.go_accel_mps2,
                              top_speed)
        e_out = _time_to_cover(s_ego + ego.LENGTH / 2 + half, ego.speed, params.go_accel_mps2,
                               top_speed)
        reach = s_other - other.LENGTH / 2 - half
        leave = s_other + other.LENGTH / 2 + half
        if speed < params.min_speed_mps:
            if reach > 0:
                continue  # waiting before the conflict: it gives way
            o_in, o_out = 0.0, np.inf  # standing in the conflict zone
        else:
            o_in, o_out = max(0.0, reach / speed), max(0.0, leave / speed)
        if e_out + critical_gap_s <= o_in or e_in >= o_out + critical_gap_s:
            continue  # the gap is accepted
        stop = s_ego - ego.LENGTH / 2 - half - params.stop_margin_m
        stop_at = stop if stop_at is None else min(stop_at, stop)
    if stop_at is None:
        return None
    # Committed: too close to stop comfortably, so clear the conflict instead of stopping in it.
    if ego.speed ** 2 / (2 * params.comfort_brake_mps2) > max(stop_at, 0.0) + 0.5:
        return None
    return max(stop_at, 0.0)


def yielding_vehicle_class():
    """The highway-env vehicle class of the yielding teacher (imported lazily: highway-env)."""
    from highway_env.vehicle.behavior import IDMVehicle

    class YieldingIDMVehicle(IDMVehicle):
        """IDM/MOBIL that gives way at conflict zones by gap acceptance (module docstring)."""

        params = GapAcceptance()
        critical_gap_s = 1.5
        stop_distance_m: float | None = None    # where it is waiting, None while it goes

        def act(self, action=None):
            super().act(action)
            if self.crashed:
                return
            cache = self.road.__dict__.setdefault("_yielding_lane_cache", {})
            stop = conflict_stop_distance(self, self.road.vehicles, self.params,
                                          self.critical_gap_s, cache)
            self.stop_distance_m = stop
            if stop is not None:
                # IDM towards a standing obstacle `stop` m ahead (its rear at the stop point):
                # desired gap s0 + v T + v Δv / (2 √(a b)) with Δv = v.
                accel = self.COMFORT_ACC_MAX * (1 - np.power(
                    max(self.speed, 0) / max(self.target_speed, 0.1), self.DELTA))
                ab = -self.COMFORT_ACC_MAX * self.COMFORT_ACC_MIN
                gap = (self.DISTANCE_WANTED + self.speed * self.TIME_WANTED
                       + self.speed * self.speed / (2 * np.sqrt(ab)))
                accel -= self.COMFORT_ACC_MAX * (gap / max(stop, 0.1)) ** 2
                # `action` is the dict the vehicle steps with (IDMVehicle.act stored it).
                self.action["acceleration"] = float(np.clip(min(self.action["acceleration"], accel),
                                                            -self.ACC_MAX, self.ACC_MAX))

        def step(self, dt):
            super().step(dt)
            # Braking stops the car; it never reverses (highway-env's kinematics would, into the
            # car waiting behind).
            self.speed = max(self.speed, 0.0)

    return YieldingIDMVehicle


class YieldingDriver(HumanDriver):
    """`yielding`: the world's IDM/MOBIL ego, made to give way at conflict zones by gap
    acceptance; its critical gap is drawn per episode from the episode's seed."""

    name = "yielding"

    def __init__(self, params: GapAcceptance = GapAcceptance()):
        self.params = params

    def attach(self, world) -> None:
        old = world.ego
        vehicle = yielding_vehicle_class().create_from(old)
        for attr in ("target_speed", "TIME_WANTED", "POLITENESS", "DELTA"):
            if attr in vars(old):
                setattr(vehicle, attr, getattr(old, attr))
        vehicle.params = self.params
        rng = np.random.default_rng([int(getattr(world, "seed", 0)), 2])
        vehicle.critical_gap_s = float(rng.uniform(*self.params.critical_gap_s))
        world.replace_ego(vehicle)
        if isinstance(getattr(world, "driver", None), dict):
            world.driver["critical_gap_s"] = vehicle.critical_gap_s


DEMONSTRATORS = ("idm", "yielding")


def demonstrator(name: str) -> HumanDriver:
    """The self-driving ego `name` (one of `DEMONSTRATORS`): plain IDM/MOBIL or the yielding
    teacher. Collection and recorded human episodes drive with it."""
    if name == "idm":
        return HumanDriver()
    if name == "yielding":
        return YieldingDriver()
    raise ValueError(f"unknown demonstrator {name!r}; choose one of {', '.join(DEMONSTRATORS)}")
