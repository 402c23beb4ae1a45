"""The one scripted aggressive driver: a neighbour of the ego turned into a threat aimed at it.

Used by the campaign attack `aggressive_neighbour` (adversary.attacks.aggressive) and by the
guard's scripted-aggressive scenes (riskmap.guard.aggressors), with the same parameters.

1. `select_adversary` picks the vehicle among those within `radius_m` of the ego, by the
   `selection` rule: STRIVE's distance rule (below) or simply the nearest vehicle.
2. `make_aggressive` replaces that vehicle's driver by `AggressiveVehicle` (same state, route and
   lane), an IDM/MOBIL driver with these changes, applied every simulation step:
   - desired speed = max(its own, the ego's speed + `speed_boost_mps`), so it catches up; or,
     with `pace_ahead_m` set, the ego's speed adjusted to sit that far ahead of the ego until it
     cuts in (it lines up beside the ego instead of overtaking it);
   - IDM time gap `time_gap_s` and jam distance `jam_distance_m` (highway-env's defaults are
     1.5 s and 10 m), MOBIL politeness 0 and no minimum gain: it tailgates and pushes in;
   - cut-in: when it drives on a lane beside the ego's lane (same road segment) and its centre
     is between `cut_in_behind_m` behind and `cut_in_ahead_m` ahead of the ego's centre, it
     changes into the ego's lane at once, whatever the gap;
   - brake check: when it is ahead of the ego in the ego's lane (or changing into it) with a
     bumper-to-bumper gap under `brake_gap_m`, it brakes at `brake_mps2` (harder than IDM's
     6 m/s² limit if asked); with `brake_hold_s` > 0 it brakes once, for that long, whatever the
     gap does meanwhile (a sustained brake check rather than braking only while close).
   It never reverses and keeps highway-env's steering and acceleration limits.
It needs no training; with the same seed it makes the same adversary do the same thing.

STRIVE's distance rule: roll the scene forward, take the distance d[i, t] of every other
agent i to the ego at each future time t, and weight the (agent, time) pairs by a softmin,

    w[i, t] = exp(-d[i, t] / tau) / sum_{j, s} exp(-d[j, s] / tau),

over agents that are not behind the ego now (their centre's forward coordinate in the ego frame
is >= 0). An agent's weight is sum_t w[i, t]; the adversary is the agent of largest weight.
`nearest` is the plain alternative: the agent nearest the ego now, behind or not.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from rasterize.errors import InputError


@dataclass(frozen=True)
class AggressiveParams:
    selection: str = "softmin"         # softmin (STRIVE distance rule) | nearest
    temperature_m: float = 2.0         # softmin temperature over distances
    horizon_s: float = 6.0             # prediction horizon of the softmin rule
    radius_m: float = 80.0             # candidates: vehicles this close to the ego at t = 0
    speed_boost_mps: float = 5.0
    time_gap_s: float = 0.3
    jam_distance_m: float = 1.0
    cut_in_behind_m: float = 5.0
    cut_in_ahead_m: float = 20.0
    brake_gap_m: float = 12.0
    brake_mps2: float = 6.0
    brake_hold_s: float = 0.0          # > 0: one brake check that lasts this long (s)
    pace_ahead_m: float | None = None  # set: sit this far ahead of the ego until the cut-in

    def __post_init__(self) -> None:
        if self.selection not in ("softmin", "nearest"):
            raise InputError(f"aggressive_neighbour selection {self.selection!r}: use softmin or nearest")
        for name in ("temperature_m", "horizon_s", "radius_m", "brake_mps2"):
            if not getattr(self, name) > 0:
                raise InputError(f"aggressive_neighbour {name} must be positive, got {getattr(self, name)}")
        for name in ("speed_boost_mps", "time_gap_s", "jam_distance_m", "cut_in_behind_m",
                     "cut_in_ahead_m", "brake_gap_m", "brake_hold_s"):
            if getattr(self, name) < 0:
                raise InputError(f"aggressive_neighbour {name} must be >= 0, got {getattr(self, name)}")


def softmin_agent_weights(distances_m: np.ndarray, eligible: np.ndarray, temperature_m: float
                          ) -> np.ndarray:
    """Agent weights [A] from future distances [A, T] (m); ineligible agents get weight 0."""
    distances_m = np.asarray(distances_m, dtype=np.float64)
    eligible = np.asarray(eligible, dtype=bool)
    if not temperature_m > 0:
        raise InputError(f"softmin temperature_m must be positive metres, got {temperature_m}")
    weights = np.zeros(distances_m.shape[0])
    if not eligible.any():
        return weights
    logits = -distances_m[eligible] / temperature_m
    logits -= logits.max()                          # stable: the largest term is exp(0)
    pair = np.exp(logits)
    weights[eligible] = pair.sum(axis=1) / pair.sum()
    return weights


def predict_positions(road, vehicles: list, horizon_s: float, step_s: float, sim_dt_s: float
                      ) -> np.ndarray:
    """Positions [len(vehicles), T, 2] (highway-env frame) at step_s, 2·step_s, ... horizon_s.

    Every vehicle follows its own behaviour model on a deep copy of the road; the live road is
    left untouched. Vehicles that leave the copy keep their last position.
    """
    twin = copy.deepcopy(road)
    index = {id(v): i for i, v in enumerate(road.vehicles)}
    twins = [twin.vehicles[index[id(v)]] for v in vehicles]
    sub_steps = round(step_s / sim_dt_s)
    out = np.zeros((len(vehicles), round(horizon_s / step_s), 2))
    for t in range(out.shape[1]):
        for _ in range(sub_steps):
            twin.act()
            twin.step(sim_dt_s)
        out[:, t] = [v.position for v in twins]
    return out


def select_adversary(road, ego, rule: str, temperature_m: float = 2.0, horizon_s: float = 6.0,
                     step_s: float = 0.5, sim_dt_s: float = 0.1, radius_m: float = 80.0):
    """The neighbour of `ego` that the rule picks (a vehicle on `road`), or None if there is none.

    Candidates are the other vehicles within `radius_m` of the ego now.
    """
    candidates = [v for v in road.vehicles
                  if v is not ego and np.linalg.norm(v.position - ego.position) <= radius_m]
    if not candidates:
        return None
    offsets = np.array([v.position - ego.position for v in candidates])
    if rule == "nearest":
        return candidates[int(np.argmin(np.linalg.norm(offsets, axis=1)))]
    if rule != "softmin":
        raise InputError(f"adversary selection rule {rule!r} is unknown; use softmin or nearest")
    forward = offsets @ np.array([np.cos(ego.heading), np.sin(ego.heading)])
    future = predict_positions(road, [ego] + candidates, horizon_s, step_s, sim_dt_s)
    distances = np.linalg.norm(future[1:] - future[:1], axis=2)
    weights = softmin_agent_weights(distances, forward >= 0.0, temperature_m)
    if not weights.any():
        return None
    return candidates[int(np.argmax(weights))]


def aggressive_vehicle_class():
    """The IDMVehicle subclass (made lazily: highway-env is imported only when episodes run)."""
    from highway_env.vehicle.behavior import IDMVehicle
    from highway_env.vehicle.kinematics import Vehicle

    class AggressiveVehicle(IDMVehicle):
        params: AggressiveParams
        target_of = None          # () -> the ego vehicle it is aimed at (changes at hand-over)

        @property
        def target(self):
            return self.target_of()

        def _ego_offset(self) -> tuple[float, float]:
            """(forward, lateral) of the ego's centre in this vehicle's frame (highway-env axes)."""
            d = self.target.position - self.position
            c, s = np.cos(self.heading), np.sin(self.heading)
            return float(d[0] * c + d[1] * s), float(-d[0] * s + d[1] * c)

        def act(self, action=None):
            if self.crashed:
                return
            p, ego = self.params, self.target
            forward, _ = self._ego_offset()
            if p.pace_ahead_m is None:
                self.target_speed = max(self.base_target_speed, float(ego.speed) + p.speed_boost_mps)
            elif not self.cut_in_started:
                # forward < 0: the ego is behind us by -forward; close the error to pace_ahead_m.
                error_m = p.pace_ahead_m + forward
                self.target_speed = max(float(ego.speed) + float(np.clip(0.5 * error_m, -5.0, 5.0)), 0.0)
            self.follow_road()
            ego_lane = ego.lane_index
            beside = (ego_lane is not None and self.lane_index is not None
                      and ego_lane[:2] == self.lane_index[:2] and ego_lane != self.lane_index)
            if beside and -p.cut_in_ahead_m <= forward <= p.cut_in_behind_m:
                # We are at most cut_in_ahead_m ahead of / cut_in_behind_m behind the ego: push in.
                self.target_lane_index, self.cut_in_started = ego_lane, True
            elif self.enable_lane_change:
                self.change_lane_policy()
            steering = float(np.clip(self.steering_control(self.target_lane_index),
                                     -self.MAX_STEERING_ANGLE, self.MAX_STEERING_ANGLE))
            front, rear = self.road.neighbour_vehicles(self, self.lane_index)
            accel = self.acceleration(ego_vehicle=self, front_vehicle=front, rear_vehicle=rear)
            if self.lane_index != self.target_lane_index:
                front, rear = self.road.neighbour_vehicles(self, self.target_lane_index)
                accel = min(accel, self.acceleration(ego_vehicle=self, front_vehicle=front,
                                                     rear_vehicle=rear))
            in_ego_lane = ego_lane in (self.lane_index, self.target_lane_index)
            gap = -forward - 0.5 * (self.LENGTH + ego.LENGTH)    # ego behind us: forward < 0
            close = in_ego_lane and forward < 0 and gap < p.brake_gap_m
            if p.brake_hold_s > 0:
                if close and not self.brake_checked:
                    self.brake_checked, self.brake_left_s = True, p.brake_hold_s
                if self.brake_left_s > 0:
                    accel, self.brake_left_s = -p.brake_mps2, self.brake_left_s - self.dt_s
            elif close:
                accel = -p.brake_mps2
            accel = float(np.clip(accel, -max(self.ACC_MAX, p.brake_mps2), self.ACC_MAX))
            accel = max(accel, -self.speed / 0.1)    # stop, never reverse (0.1 s steps)
            Vehicle.act(self, {"steering": steering, "acceleration": accel})

    return AggressiveVehicle


def make_aggressive(vehicle, target_of, params: AggressiveParams, dt_s: float = 0.1):
    """An AggressiveVehicle at `vehicle`'s state, aimed at the vehicle `target_of()` returns;
    `dt_s`: the simulation step (s), for timed brake checks."""
    cls = aggressive_vehicle_class()
    new = cls(vehicle.road, vehicle.position.copy(), heading=vehicle.heading, speed=vehicle.speed,
              target_lane_index=vehicle.target_lane_index, target_speed=vehicle.target_speed,
              route=list(vehicle.route) if vehicle.route else None,
              timer=getattr(vehicle, "timer", None))
    new.params, new.target_of, new.dt_s = params, target_of, dt_s
    new.brake_checked, new.brake_left_s, new.cut_in_started = False, 0.0, False
    new.base_target_speed = float(vehicle.target_speed)
    new.TIME_WANTED = params.time_gap_s           # instance attributes shadow IDM's defaults
    new.DISTANCE_WANTED = params.jam_distance_m + new.LENGTH
    new.POLITENESS = 0.0
    new.LANE_CHANGE_MIN_ACC_GAIN = 0.0
    new.LANE_CHANGE_MAX_BRAKING_IMPOSED = 9.0
    new.DELTA = getattr(vehicle, "DELTA", new.DELTA)
    new.enable_lane_change = getattr(vehicle, "enable_lane_change", True)
    return new


def install_aggressive_neighbour(run, params: AggressiveParams):
    """Turn the neighbour that `params.selection` picks in `run` (a `riskmap.sim.worlds.episode.Episode`)
    into an `AggressiveVehicle` aimed at the ego; returns it, or None when nobody qualifies.

    The ego is looked up at every step (`run.ego`): a guard or planner may replace the ego
    vehicle object after this runs, and the aggressor follows that one.
    """
    road, ego = run.base.road, run.ego
    chosen = select_adversary(road, ego, params.selection, params.temperature_m, params.horizon_s,
                              sim_dt_s=run.dt, radius_m=params.radius_m)
    if chosen is None:
        return None
    new = make_aggressive(chosen, lambda: run.ego, params, run.dt)
    road.vehicles[road.vehicles.index(chosen)] = new
    run.recorder.adopt(new, chosen)
    return new
