"""Planners that break the planner contract on purpose, for `riskmap check-planner` and plug-in
tests: SPEC `py:tests.broken_planners:Broken?fault=NAME` (run from the repository root)."""

from __future__ import annotations

import time

import numpy as np

from rasterize.frames import ego_pose
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS, Plan

FAULTS = ("none", "world_frame", "kmh", "nan", "shape", "raise", "unseeded", "slow", "not_a_plan",
          "swapped_axes")


class Broken:
    """Constant velocity, with `fault` added (several joined by "+": `kmh+unseeded`)."""

    def __init__(self, fault: str = "none", seed: int = 0):
        faults = set(fault.replace("+", " ").split())   # a SPEC query reads "+" as a space
        if not faults <= set(FAULTS):
            raise ValueError(f"fault must be one of {FAULTS}")
        self.faults, self.seed = faults, seed
        self.rng = np.random.default_rng(None if "unseeded" in faults else seed)

    def reset(self, scene) -> None:
        pass

    def plan(self, scene):
        speed = float(scene.ego_state()[4])
        ahead = speed * PLAN_DT_S * np.arange(1, PLAN_STEPS + 1)
        waypoints = np.stack([ahead, np.zeros(PLAN_STEPS)], axis=1)
        waypoints[:, 1] += 0.01 * self.rng.standard_normal(PLAN_STEPS)
        if "world_frame" in self.faults:
            origin, _ = ego_pose(scene)
            waypoints = waypoints + origin + 500.0
        if "kmh" in self.faults:
            waypoints = waypoints * 3.6
        if "nan" in self.faults:
            waypoints[5] = np.nan
        if "shape" in self.faults:
            waypoints = waypoints[:6]
        if "raise" in self.faults:
            raise RuntimeError("this planner always fails")
        if "slow" in self.faults:
            time.sleep(0.6)
        if "not_a_plan" in self.faults:
            return waypoints
        if "swapped_axes" in self.faults:
            waypoints = waypoints[:, ::-1].copy()
        return Plan(waypoints)


def not_a_planner(seed: int = 0):
    return "I am a string"
