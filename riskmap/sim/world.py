"""What the closed loop (`riskmap.sim.rollout.drive_world`) needs from a world it drives the ego in.

Worlds: `Episode` (highway-env traffic), `LogReplayEpisode` (traffic replaying a recorded
episode) and `CommonRoadWorld` (a CommonRoad recording on a road built from its lanelets). The
loop only plans, tracks the plan and measures; everything that differs between worlds (how
the scene is assembled, what counts as a collision, when the episode ends) stays behind this.
"""

from __future__ import annotations

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
