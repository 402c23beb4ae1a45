"""What the closed loop (`riskmap.sim.loop.rollout.drive_world`) needs from a world it drives the ego in.

Worlds: `Episode` (highway-env traffic), `LogReplayEpisode` (traffic replaying a recorded
episode) and `CommonRoadWorld` (a CommonRoad recording on a road built from its lanelets). The
loop only plans, tracks the plan and measures; everything that differs between worlds (how
the scene is assembled, what counts as a collision, when the episode ends) stays behind this.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from rasterize.scene import Scene


class World(Protocol):
    dt: float                  # seconds per step (the control period)
    crashed: bool
    off_network: bool          # the ego left the road

    @property
    def ego(self):
        """The highway-env vehicle that is the ego now (positions in highway-env's frame)."""

    @property
    def time_s(self) -> float:
        """Simulated seconds."""

    @property
    def done(self) -> bool:
        """No further step: the ego crashed, left the road, or the world has run out."""

    def hand_over(self, history_s: float) -> tuple[object, Scene]:
        """Give the ego to a vehicle that the planner commands (`command(accel, steer_ccw)`);
        returns that vehicle and the scene the planner is reset with."""

    def scene(self, history_s: float) -> Scene:
        """What the planner sees now: the ego's `history_s` of history and the others."""

    def ego_state(self) -> np.ndarray:
        """The ego's state now [6] (x, y, heading_x, heading_y, speed, yaw_rate), world frame."""

    def step(self) -> None:
        """Advance one `dt`: every vehicle acts, then collisions and leaving the road are found."""

    def min_gap(self, radius_m: float) -> float:
        """Smallest box gap (m) from the ego to another vehicle within `radius_m`; inf if none."""

    def cap_ego_accel(self, cap: Callable[[], float | None]) -> None:
        """For the rest of the episode every acceleration (m/s²) the ego's vehicle is commanded
        is at most `cap()`, asked at each command (None: no cap now). The guard's slowdown frames
        hold the ego to a deceleration this way, whatever the planner's controller asks for."""

    def history(self, history_s: float, dt_s: float, radius_m: float) -> Scene:
        """The scene now with `history_s` of everyone's past sampled every `dt_s`, others within
        `radius_m`, no lanes: what the guard's accident predictor scores."""


def recorded_history(recorder, history_s: float, dt_s: float, radius_m: float) -> Scene:
    """`World.history` from a `rasterize.highway.TrafficRecorder`: its last step, no lanes."""
    return recorder.scene(recorder.num_steps - 1, history_s=history_s, future_s=0.0, dt_s=dt_s,
                          radius_m=radius_m, lanes=False)
