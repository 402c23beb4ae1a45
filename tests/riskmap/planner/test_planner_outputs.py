"""What a risk-map plan carries besides its waypoints: the state visitation on demand."""

import pickle

import numpy as np
import torch

from rasterize.maps import start_cell
from riskmap.planner.model import ModelConfig, RiskMapGenerator
from riskmap.planner.riskmap_planner import RiskMapPlanner
from riskmap.planner.vi import state_visitation
from tests.scenes import UNIT_GRID, UNIT_RASTER, constant_velocity_scene, straight_lane


def _plan():
    torch.manual_seed(0)
    planner = RiskMapPlanner(RiskMapGenerator(ModelConfig(resolution=20)), UNIT_RASTER, UNIT_GRID,
                             horizon=24, goal_variance=5.0)
    return planner.plan(constant_velocity_scene(lanes=[straight_lane(0.0)])), planner


def test_svf_is_computed_when_read_and_equals_the_state_visitation_of_the_policy():
    plan, planner = _plan()
    assert "svf" not in plan.timings_s                        # not paid for by the replan
    expected = state_visitation(torch.from_numpy(plan.policy)[None],
                                torch.tensor([start_cell(planner.grid)]), planner.horizon)[0][0]
    np.testing.assert_array_equal(plan.svf, expected.numpy())
    assert plan.timings_s["svf"] > 0 and plan.svf is plan.svf   # computed once
    assert plan.timings_s["total"] == sum(plan.timings_s[k] for k in ("raster", "network", "vi",
                                                                      "sampler"))


def test_a_pickled_plan_carries_its_svf():
    plan, _ = _plan()
    copy = pickle.loads(pickle.dumps(plan))
    np.testing.assert_array_equal(copy.svf, plan.svf)
    np.testing.assert_array_equal(copy.waypoints, plan.waypoints)
