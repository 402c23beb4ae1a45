"""Perception degradation for the IDM/MOBIL ego, which reads the simulator instead of a `Scene`.

`perceiving_idm_class()` builds an IDM/MOBIL vehicle that, each time it acts, sees the other
vehicles as a degraded sensor would report them: `latency_steps` × 0.5 s late, only within
`sensing_range_m`, each missing with `drop_probability` and offset by Gaussian position and
heading noise. As for a planner that replans at 2 Hz, drops and noise are drawn once per 0.5 s
frame and held in between; positions still move at the control rate. The ego then decides (IDM
acceleration, MOBIL lane changes) on these "ghost" vehicles; the real vehicles still collide.
"""

from __future__ import annotations

import copy

import numpy as np

FRAME_S = 0.5          # a perception frame, as the planners' replanning period


def perceiving_idm_class():
    from highway_env.vehicle.behavior import IDMVehicle

    class PerceivingIDMVehicle(IDMVehicle):
        def configure_perception(self, params: dict[str, float], seed: int, dt_s: float) -> None:
            self.perception, self.perception_seed, self.dt_s = params, seed, dt_s
            self.history: dict[int, list[tuple]] = {}     # id(vehicle) -> [(position, heading, speed)]
            self.steps = 0

        def _ghosts(self, others: list) -> list:
            p = self.perception
            per_frame = max(1, round(FRAME_S / self.dt_s))
            frame = self.steps // per_frame
            delay = round(p["latency_steps"]) * per_frame
            # The same draws for every control step of a frame: held, like a 2 Hz sensor.
            rng = np.random.default_rng([self.perception_seed, frame, 7])
            dropped = rng.random(len(others)) < p["drop_probability"]
            noise = rng.normal(size=(len(others), 3))
            ghosts = []
            for index, other in enumerate(others):
                past = self.history[id(other)]
                if delay >= len(past) or dropped[index]:
                    continue                               # not seen (yet, or this frame)
                position, heading, speed = past[-1 - delay]
                if np.linalg.norm(position - self.position) > p["sensing_range_m"]:
                    continue
                ghost = copy.copy(other)
                ghost.position = position + noise[index, :2] * p["position_noise_m"]
                ghost.heading = heading + noise[index, 2] * p["heading_noise_rad"]
                ghost.speed = speed
                ghost.lane_index = self.road.network.get_closest_lane_index(ghost.position,
                                                                            ghost.heading)
                ghost.lane = self.road.network.get_lane(ghost.lane_index)
                ghosts.append(ghost)
            return ghosts

        def act(self, action=None):
            road = self.road
            others = [v for v in road.vehicles if v is not self]
            for other in others:
                self.history.setdefault(id(other), []).append(
                    (other.position.copy(), float(other.heading), float(other.speed)))
            real = road.vehicles
            road.vehicles = [self, *self._ghosts(others)]
            try:
                super().act(action)
            finally:
                road.vehicles = real
            self.steps += 1

    return PerceivingIDMVehicle
