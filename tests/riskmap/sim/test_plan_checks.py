"""The first-waypoint check names what went wrong: a plan a few metres ahead of what the speed
allows (an overshoot, as a coarse-grid planner makes) is not diagnosed as a frame error, and a
plan in world coordinates still is."""

import numpy as np

from riskmap.sim.loop.plan import Plan
from riskmap.sim.loop.plan_checks import plan_problems


def test_an_overshoot_and_a_wrong_frame_are_told_apart():
    ahead = np.stack([5.4 * 0.5 * np.arange(1, 13), np.zeros(12)], axis=1)     # 10.8 m/s
    assert plan_problems(Plan(ahead), speed=10.8) == []
    overshoot = ahead + [2.6 + 2.6, 0.0]                       # first waypoint 7.9 m ahead
    problem = plan_problems(Plan(overshoot), speed=10.8)
    assert len(problem) == 1 and "runs ahead of the car" in problem[0] and "7.9 m from the ego" in problem[0]
    world = ahead + [350.0, -20.0]
    problem = plan_problems(Plan(world), speed=10.8)
    assert len(problem) == 1 and "not world coordinates" in problem[0]
