"""Hand-built scenes for tests: every number here can be checked by hand."""

from __future__ import annotations

import numpy as np

from rasterize.config import Extent, GridConfig, RasterConfig
from rasterize.scene import Lane, LineType, Scene

# 1 m pixels over 20 m x 20 m centred on the ego: pixel (row, col) covers
# x in (10 - row - 1, 10 - row], y in (10 - col - 1, 10 - col].
UNIT_RASTER = RasterConfig(Extent(10.0, 10.0, 10.0, 10.0), rows=20, cols=20, history_s=1.0)
UNIT_GRID = GridConfig(Extent(10.0, 10.0, 10.0, 10.0), rows=20, cols=20)


def state(x, y, heading, speed=0.0, yaw_rate=0.0):
    return [x, y, np.cos(heading), np.sin(heading), speed, yaw_rate]


def straight_lane(y_centre: float, x0: float = -30.0, x1: float = 30.0, width: float = 4.0,
                  left=LineType.DASHED, right=LineType.SOLID) -> Lane:
    xs = np.array([x0, x1])
    centre = np.stack([xs, np.full(2, y_centre)], axis=1)
    return Lane(centre, centre + [0, width / 2], centre - [0, width / 2], left, right, width, 0.0)


def constant_velocity_scene(n_past: int = 2, n_future: int = 4, dt: float = 0.5,
                            ego_speed: float = 2.0, lanes=()) -> Scene:
    """Ego at the origin heading east (+x) at `ego_speed`; one agent 5 m ahead-left, same speed.

    Ego box 4 m x 2 m; agent box 4 m x 2 m heading north (+y) at (5, 3).
    """
    t = (np.arange(-n_past, n_future + 1)) * dt
    ego = [state(ego_speed * ti, 0.0, 0.0, ego_speed) for ti in t]
    agent = [state(5.0, 3.0, np.pi / 2) for _ in t]
    states = np.array([ego, agent])
    valid = np.ones(states.shape[:2], dtype=bool)
    return Scene(states, valid, sizes=np.array([[4.0, 2.0], [4.0, 2.0]]), kinds=np.zeros(2),
                 ego_index=0, current_index=n_past, dt=dt, lanes=tuple(lanes))
