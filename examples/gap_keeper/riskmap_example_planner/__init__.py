"""GapKeeper: follow the route at a desired speed, keeping a time gap to the vehicle ahead.

It uses only the toolkit's public contract: `reset(scene)`, `plan(scene) -> Plan` with 12
waypoints in the ego frame (x forward, y left, metres) at 0.5 s steps, and the frame helpers of
`rasterize.frames`.
"""

from __future__ import annotations

import numpy as np

from rasterize.frames import ego_from_world, ego_pose
from riskmap import PLAN_DT_S, PLAN_STEPS, Plan     # the public planner contract


class GapKeeper:
    """Speeds in m/s, gaps in metres, accelerations in m/s², times in seconds."""

    def __init__(self, desired_speed: float = 25.0, headway_s: float = 1.5, min_gap_m: float = 4.0,
                 max_accel: float = 1.5, max_decel: float = 6.0, seed: int = 0):
        if desired_speed <= 0 or headway_s <= 0 or max_accel <= 0 or max_decel <= 0:
            raise ValueError("desired_speed, headway_s, max_accel and max_decel must be positive")
        self.desired_speed, self.headway_s, self.min_gap_m = desired_speed, headway_s, min_gap_m
        self.max_accel, self.max_decel = max_accel, max_decel

    def reset(self, scene) -> None:
        pass

    def plan(self, scene) -> Plan:
        origin, heading = ego_pose(scene)
        path = self._path(scene, origin, heading)
        gap, leader_speed = self._leader(scene, origin, heading, path)
        speed = float(scene.ego_state()[4])
        travelled, s = [], 0.0
        for _ in range(PLAN_STEPS):
            safe = max(0.0, gap - self.min_gap_m) / self.headway_s
            target = min(self.desired_speed, safe)
            accel = float(np.clip((target - speed) / PLAN_DT_S, -self.max_decel, self.max_accel))
            step = max(0.0, speed * PLAN_DT_S + 0.5 * accel * PLAN_DT_S ** 2)
            speed = max(0.0, speed + accel * PLAN_DT_S)
            s += step
            gap += leader_speed * PLAN_DT_S - step
            travelled.append(s)
        return Plan(self._along(path, np.asarray(travelled)))

    @staticmethod
    def _path(scene, origin, heading) -> np.ndarray:
        """The route ahead in the ego frame [K, 2], extended straight on to 300 m."""
        if scene.route_xy is not None and len(scene.route_xy) >= 2:
            path = ego_from_world(scene.route_xy, origin, heading)
            path = path[path[:, 0] >= -1.0] if (path[:, 0] >= -1.0).sum() >= 2 else path
        else:
            path = np.array([[0.0, 0.0], [1.0, 0.0]])
        end, before = path[-1], path[-2]
        direction = (end - before) / max(np.linalg.norm(end - before), 1e-6)
        return np.vstack([[0.0, 0.0], path, end + 300.0 * direction])

    @staticmethod
    def _along(path: np.ndarray, distances: np.ndarray) -> np.ndarray:
        """Points at arc lengths `distances` along `path`."""
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        return np.stack([np.interp(distances, arc, path[:, 0]),
                         np.interp(distances, arc, path[:, 1])], axis=1)

    @staticmethod
    def _leader(scene, origin, heading, path) -> tuple[float, float]:
        """(gap in m, speed in m/s) of the nearest agent within 2.5 m of the path ahead."""
        now = scene.current_index
        others = [i for i in range(scene.num_agents)
                  if i != scene.ego_index and scene.valid[i, now]]
        best = (np.inf, 0.0)
        if not others:
            return best
        xy = ego_from_world(scene.states[others, now, :2], origin, heading)
        dense = GapKeeper._along(path, np.arange(0.0, 150.0, 1.0))
        for k, point in zip(others, xy):
            distances = np.linalg.norm(dense - point, axis=1)
            nearest = int(np.argmin(distances))
            if distances[nearest] > 2.5 or nearest == 0:
                continue
            half_lengths = 0.5 * (scene.sizes[scene.ego_index, 0] + scene.sizes[k, 0])
            gap = float(nearest) - half_lengths
            if gap < best[0]:
                best = (gap, float(scene.states[k, now, 4]))
        return best


def from_spec(arg: str, seed: int = 0) -> GapKeeper:
    """Entry point `gap-keeper`: SPEC `gap-keeper:SPEED`, SPEED the desired speed in m/s."""
    try:
        speed = float(arg)
    except ValueError:
        raise ValueError(f"gap-keeper:{arg}: give the desired speed in m/s, e.g. gap-keeper:25"
                         ) from None
    return GapKeeper(desired_speed=speed, seed=seed)
