"""Baseline planners behind the `Planner` protocol that need no training."""

from __future__ import annotations

import numpy as np

from rasterize.scene import Scene
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS, Plan


class ConstantVelocityPlanner:
    """`cv`: keep the current speed and heading for 6 s (waypoints straight ahead)."""

    def reset(self, scene: Scene) -> None:
        pass

    def plan(self, scene: Scene) -> Plan:
        speed = float(scene.ego_state()[4])
        x = speed * PLAN_DT_S * np.arange(1, PLAN_STEPS + 1)
        return Plan(np.stack([x, np.zeros(PLAN_STEPS)], axis=1))
