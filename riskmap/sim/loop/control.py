"""Tracking a plan: pure pursuit for steering, a PI loop for speed, at the control rate.

Waypoints arrive in the ego frame of the moment they were planned; the controller pins them to
the world then, so that between replans it keeps tracking the same path while the ego moves.
Angles are in the toolkit's world frame (counter-clockwise); `PlannedVehicle` converts to
highway-env's clockwise steering.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.frames import world_from_ego
from rasterize.geometry import Polyline
from rasterize.timebase import PLAN_DT_S, PLAN_STEPS

# Waypoint times of a plan (s after it was made): 0.5, 1.0, ... 6.0
PLAN_TIMES_S = PLAN_DT_S * np.arange(1, PLAN_STEPS + 1)


@dataclass(frozen=True)
class ControllerConfig:
    lookahead_min_m: float = 6.0
    lookahead_time_s: float = 1.2       # lookahead distance = max(min, speed × time): long
                                        # enough to smooth over the grid path's staircase
    wheelbase_m: float = 5.0            # highway-env's bicycle: yaw rate ≈ v·δ / vehicle length
    kp_per_s: float = 1.2               # acceleration per m/s of speed error
    ki_per_s2: float = 0.15
    accel_min_mps2: float = -6.0
    accel_max_mps2: float = 3.0
    max_steer_rad: float = 0.6


class TrackingController:
    def __init__(self, config: ControllerConfig = ControllerConfig()):
        self.config = config
        self.path = None          # [K + 1, 2] world: plan origin then the waypoints
        self._line = None         # the path as a Polyline
        self._integral = 0.0
        self._braking = False
        self._dt = PLAN_DT_S      # seconds between the plan's waypoints
        self._knot0 = PLAN_DT_S / 2   # time (s) of the first speed of the profile

    def set_plan(self, waypoints_ego: np.ndarray, origin: np.ndarray, heading: float,
                 dt_s: float = PLAN_DT_S, speeds: np.ndarray | None = None) -> None:
        """Pin a plan made at `origin`/`heading`: waypoints `dt_s` apart (s), with the speed at
        each (m/s) or None to take the speeds their spacing implies (`riskmap.sim.loop.plan.Plan`)."""
        pts = np.concatenate([[[0.0, 0.0]], np.asarray(waypoints_ego, dtype=np.float64)])
        self.path = world_from_ego(pts, origin, heading)
        self._line = Polyline(self.path)
        self._dt = float(dt_s)
        self._braking = False
        if speeds is None:
            # Speed the plan implies over each interval, taken at the intervals' midpoints.
            self._speeds = self._line.lengths / self._dt
            self._knot0 = self._dt / 2
        else:
            # Speeds given at the waypoints' own times (dt, 2 dt, ...).
            self._speeds = np.asarray(speeds, dtype=np.float64)
            self._knot0 = self._dt

    def brake(self) -> None:
        """Stop on the spot: the planner had no plan (`riskmap.sim.loop.plan.NoSolution`), so brake at
        the hardest rate, wheels straight, until the next plan."""
        self._braking = True

    def target_speed(self, since_plan_s: float) -> float:
        """The plan's mean speed over the interval `since_plan_s` falls in."""
        k = int(np.clip(since_plan_s // self._dt, 0, len(self._speeds) - 1))
        return float(self._speeds[k])

    def speed_profile(self, since_plan_s: float) -> tuple[float, float]:
        """(speed m/s, acceleration m/s²) the plan asks for at `since_plan_s`: the plan's speeds
        at their times (the interval means at the intervals' midpoints, or the given speeds at the
        waypoints' times) joined linearly (extended before the first)."""
        mids = self._knot0 + self._dt * np.arange(len(self._speeds))
        if len(mids) < 2:
            return float(self._speeds[0]), 0.0
        k = int(np.clip(np.searchsorted(mids, since_plan_s) - 1, 0, len(mids) - 2))
        slope = (self._speeds[k + 1] - self._speeds[k]) / self._dt
        if since_plan_s > mids[-1]:
            return float(self._speeds[-1]), 0.0
        return float(self._speeds[k] + slope * (since_plan_s - mids[k])), float(slope)

    def _lookahead_point(self, position: np.ndarray, distance: float) -> np.ndarray:
        line = self._line
        i, t, _ = line.nearest(position)
        # Segment lengths floored at 1e-6 m (a plan that stands still has zero-length ones).
        target_s = line.arc[i] + t * max(line.lengths[i], 1e-6) + distance
        # Beyond the plan: continue straight along its last segment.
        direction = (line.segments[-1] / max(line.lengths[-1], 1e-6) if line.length > 1e-6
                     else np.zeros(2))
        return line.point_at(target_s, beyond=direction)

    def action(self, position: np.ndarray, heading: float, speed: float, since_plan_s: float,
               dt: float) -> tuple[float, float]:
        """(acceleration m/s², steering rad counter-clockwise) for the next control step."""
        cfg = self.config
        if self._braking:
            return max(cfg.accel_min_mps2, -speed / dt), 0.0      # to a stop, never into reverse
        if self.path is None:
            return cfg.accel_min_mps2, 0.0
        # Feed-forward the plan's own acceleration: feedback alone on the interval's mean speed
        # lags a braking plan by about a second (a plan to stop from 7 m/s within 7 m was
        # tracked at -1 m/s², and the ego rolled into the crossing it had planned to wait for).
        v_target, a_plan = self.speed_profile(since_plan_s)
        error = v_target - speed
        self._integral = float(np.clip(self._integral + error * dt, -5.0, 5.0))
        accel = a_plan + cfg.kp_per_s * error + cfg.ki_per_s2 * self._integral
        accel = float(np.clip(accel, cfg.accel_min_mps2, cfg.accel_max_mps2))
        accel = max(accel, -speed / dt)       # brake to a stop, never into reverse
        if self._line.length < 0.5:           # a plan to stay put
            return accel, 0.0
        lookahead = max(cfg.lookahead_min_m, speed * cfg.lookahead_time_s)
        target = self._lookahead_point(position, lookahead)
        d = target - position
        alpha = np.arctan2(d[1], d[0]) - heading
        alpha = (alpha + np.pi) % (2 * np.pi) - np.pi
        curvature = 2.0 * np.sin(alpha) / max(np.linalg.norm(d), 1e-6)
        # Invert highway-env's bicycle: yaw rate = v sin(beta) / (L/2), tan(delta) = 2 tan(beta).
        sin_beta = np.clip(curvature * cfg.wheelbase_m / 2.0, -0.99, 0.99)
        steer = float(np.arctan(2.0 * np.tan(np.arcsin(sin_beta))))
        return accel, float(np.clip(steer, -cfg.max_steer_rad, cfg.max_steer_rad))


def capped_accel(accel: float, cap) -> float:
    """`accel` held at most `cap()` (`riskmap.sim.loop.world.World.cap_ego_accel`); as asked where
    there is no cap or `cap()` is None."""
    limit = None if cap is None else cap()
    return accel if limit is None else min(accel, limit)


def planned_vehicle_class():
    """A highway-env vehicle that keeps its route bookkeeping but drives by the action it is given."""
    from highway_env.vehicle.controller import ControlledVehicle

    class PlannedVehicle(ControlledVehicle):
        accel_cap = None                  # set by its world's `cap_ego_accel`

        def act(self, action=None):
            self.follow_road()            # keeps lane and route up to date, as the IDM ego does
            if action is not None:
                self.action = dict(action)

        def command(self, accel: float, steer_ccw: float) -> None:
            accel = capped_accel(accel, self.accel_cap)
            self.action = {"acceleration": accel, "steering": -steer_ccw}   # highway-env: clockwise

    return PlannedVehicle


def hand_over_to_planner(episode) -> object:
    """Replace the episode's ego by a PlannedVehicle with the same state and route."""
    cls = planned_vehicle_class()
    old = episode.ego
    new = cls(old.road, old.position.copy(), old.heading, old.speed,
              target_lane_index=old.target_lane_index, target_speed=old.target_speed,
              route=list(old.route) if old.route else None)
    new.action = {"acceleration": 0.0, "steering": 0.0}
    episode.replace_ego(new)
    return new
