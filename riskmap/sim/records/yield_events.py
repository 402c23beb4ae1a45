"""Yielding events: the ego waited while a crossing vehicle passed ahead of it.

One event per wait: a stretch of at least `min_wait_s` during which the ego stood (slower than
`stopped_mps`) and at least one other vehicle, moving and heading across the ego's direction
(more than `crossing_angle_deg` off it, either way), was on the ego's path ahead (within
`ahead_m` in front and `path_half_width_m` to either side of the ego's centre line). A queue
behind a stopped car is no yielding event (the car ahead goes the ego's way); neither is a
stop with nothing crossing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.frames import ego_from_world, ego_pose
from rasterize.scene import SPEED, Scene


@dataclass(frozen=True)
class YieldEventConfig:
    stopped_mps: float = 0.5
    min_wait_s: float = 1.0
    ahead_m: float = 30.0
    path_half_width_m: float = 2.5
    crossing_angle_deg: float = 30.0


def crossing_ahead(scene: Scene, config: YieldEventConfig) -> bool:
    """Whether a moving vehicle crosses the ego's path ahead at the scene's current time."""
    now, ego = scene.current_index, scene.ego_index
    others = np.flatnonzero(scene.valid[:, now])
    others = others[others != ego]
    if len(others) == 0:
        return False
    state = scene.states[others, now]
    origin, heading = ego_pose(scene)
    local = ego_from_world(state[:, 0:2], origin, heading)      # x ahead, y left
    ego_dir = np.array([np.cos(heading), np.sin(heading)])
    cos_angle = np.abs(state[:, 2:4] @ ego_dir)                 # either direction along the path
    crossing = cos_angle < np.cos(np.radians(config.crossing_angle_deg))
    on_path = (local[:, 0] > 0) & (local[:, 0] < config.ahead_m) \
        & (np.abs(local[:, 1]) < config.path_half_width_m)
    moving = state[:, SPEED] > config.stopped_mps
    return bool((crossing & on_path & moving).any())


class YieldEventCounter:
    """Fed once per control step (`update`); `events` counts finished waits that were yields."""

    def __init__(self, dt: float, config: YieldEventConfig = YieldEventConfig()):
        self.dt, self.config = dt, config
        self.events = 0
        self._wait_s, self._crossed = 0.0, False

    def update(self, ego_speed_mps: float, scene_now) -> None:
        """`scene_now()` builds the current scene; called only while the ego stands."""
        if ego_speed_mps >= self.config.stopped_mps:
            self._close()
            return
        self._wait_s += self.dt
        if not self._crossed:
            self._crossed = crossing_ahead(scene_now(), self.config)

    def finish(self) -> int:
        self._close()
        return self.events

    def _close(self) -> None:
        if self._wait_s >= self.config.min_wait_s - 1e-9 and self._crossed:
            self.events += 1
        self._wait_s, self._crossed = 0.0, False
