"""The risk-limited goal: held short where the risk map blocks the ego's route, the same rule in
training (per sample, with its own goal variance) and in the planner."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from rasterize.config import Extent, GridConfig
from rasterize.errors import InputError
from rasterize.frames import grid_from_ego
from rasterize.maps import ROUTE_POINTS, route_cells
from rasterize.scene import Scene
from riskmap.planner.irl import IRLConfig, goal_cells, goal_log_map, irl_step
from riskmap.planner.risk_goal import RiskGoalConfig, risk_goal_cell, risk_goal_cells
from tests.scenes import state

# 1 m cells, 100 m ahead and 10 m behind, 10 m either side: cell (row, col) holds
# x in (100 - row - 1, 100 - row], y in (10 - col - 1, 10 - col].
GRID = GridConfig(Extent(100.0, 10.0, 10.0, 10.0), rows=110, cols=20)


def _scene(speed: float = 20.0, route_to_m: float = 90.0) -> Scene:
    """The ego at the origin heading +x at `speed`, its route straight ahead to `route_to_m`."""
    states = np.array([[state(-speed * 0.5, 0.0, 0.0, speed), state(0.0, 0.0, 0.0, speed)]])
    return Scene(states, np.ones((1, 2), dtype=bool), sizes=np.array([[4.0, 2.0]]), kinds=np.zeros(1),
                 ego_index=0, current_index=1, dt=0.5,
                 route_xy=np.column_stack([np.linspace(0.0, route_to_m, 13), np.zeros(13)]))


def _cell_at(x_m: float) -> tuple[int, int]:
    r, c = grid_from_ego(np.array([x_m, 0.0]), GRID)
    return int(r), int(c)


def test_route_cells_run_from_the_ego_every_metre_to_the_route_end_then_pad():
    cells = route_cells(_scene(route_to_m=40.0), GRID)
    assert cells.shape == (ROUTE_POINTS, 2)
    valid = cells[cells[:, 0] >= 0]
    assert len(valid) == 41                                   # 0, 1, ..., 40 m
    assert tuple(valid[0]) == _cell_at(0.0) and tuple(valid[-1]) == _cell_at(40.0)
    assert (np.diff(valid[:, 0]) == -1).all()                 # one row (1 m) further each point
    assert (cells[41:] == -1).all()
    assert (route_cells(replace(_scene(), route_xy=None), GRID) == -1).all()


def test_a_clear_route_keeps_the_route_rule_goal():
    reward = np.full((GRID.rows, GRID.cols), -1.0)
    assert risk_goal_cell(reward, route_cells(_scene(), GRID), 20.0, RiskGoalConfig()) is None


def test_a_blocked_point_within_reach_holds_the_goal_margin_short_of_it_or_at_the_stopping_distance():
    config = RiskGoalConfig(threshold=-6.0, skip_m=8.0, reach_s=1.5, margin_m=5.0, min_goal_m=10.0,
                            brake_mps2=6.0)
    reward = np.full((GRID.rows, GRID.cols), -1.0)
    reward[_cell_at(30.0)] = -7.0
    # at 10 m/s the checked stretch ends at 8 + 10 × 1.5 = 23 m: 30 m is not checked
    assert risk_goal_cell(reward, route_cells(_scene(10.0), GRID), 10.0, config) is None
    # at 15 m/s it ends at 30.5 m: held 5 m short, at 25 m (the stopping distance 15² / 12 = 18.75 m
    # is nearer)
    assert risk_goal_cell(reward, route_cells(_scene(15.0), GRID), 15.0, config) == _cell_at(25.0)
    # at 20 m/s the stopping distance, 20² / 12 = 33.3 m, is further than 25 m: the goal sits at 34 m
    assert risk_goal_cell(reward, route_cells(_scene(20.0), GRID), 20.0, config) == _cell_at(34.0)


def test_points_in_the_ego_footprint_or_beyond_reach_do_not_block():
    config = RiskGoalConfig(skip_m=8.0, reach_s=1.0)
    reward = np.full((GRID.rows, GRID.cols), -1.0)
    reward[_cell_at(4.0)] = -20.0                              # under the ego itself
    reward[_cell_at(60.0)] = -20.0                             # beyond 8 + 20 m
    assert risk_goal_cell(reward, route_cells(_scene(), GRID), 20.0, config) is None


def test_a_block_next_to_the_route_counts_only_within_the_footprint_width():
    reward = np.full((GRID.rows, GRID.cols), -1.0)
    r, c = _cell_at(20.0)
    reward[r, c + 1] = -9.0
    cells = route_cells(_scene(10.0), GRID)
    assert risk_goal_cell(reward, cells, 10.0, RiskGoalConfig(half_width_cells=0)) is None
    assert risk_goal_cell(reward, cells, 10.0, RiskGoalConfig(half_width_cells=1)) == _cell_at(15.0)


def test_a_goal_held_no_nearer_than_the_route_rule_goal_is_dropped():
    reward = np.full((GRID.rows, GRID.cols), -1.0)
    reward[_cell_at(15.0)] = -7.0
    # at 20 m/s the stopping distance (33.3 m) lies beyond the route's end at 20 m: holding the
    # goal there would send the ego further, not nearer, so the route rule's goal stands
    assert risk_goal_cell(reward, route_cells(_scene(20.0, route_to_m=20.0), GRID), 20.0,
                          RiskGoalConfig()) is None
    assert risk_goal_cell(reward, route_cells(_scene(10.0, route_to_m=20.0), GRID), 10.0,
                          RiskGoalConfig()) == _cell_at(10.0)


def test_bad_settings_are_refused():
    with pytest.raises(InputError):
        RiskGoalConfig(goal_variance=0.0)
    with pytest.raises(InputError):
        RiskGoalConfig(skip_m=-1.0)


def test_batch_goals_take_the_held_cell_and_its_variance_only_where_blocked():
    reward = np.full((2, GRID.rows, GRID.cols), -1.0)
    reward[1][_cell_at(20.0)] = -9.0        # checked up to 8 + 10 × 1.5 = 23 m
    cells = np.stack([route_cells(_scene(10.0), GRID)] * 2)
    route_goal = np.array([_cell_at(90.0)] * 2)
    out, variance = risk_goal_cells(reward, cells, np.array([10.0, 10.0]), route_goal, 5.0, RiskGoalConfig())
    assert tuple(out[0]) == _cell_at(90.0) and variance[0] == 5.0
    assert tuple(out[1]) == _cell_at(15.0) and variance[1] == RiskGoalConfig().goal_variance


def test_per_sample_goal_variance_matches_one_map_per_sample_in_float64():
    cells = torch.tensor([[3, 4], [10, 2]])
    variance = torch.tensor([5.0, 0.5], dtype=torch.float64)
    both = goal_log_map(cells, 12, 8, variance, torch.float64)
    for i in range(2):
        alone = goal_log_map(cells[i:i + 1], 12, 8, float(variance[i]), torch.float64)
        torch.testing.assert_close(both[i:i + 1], alone)
    r, c = 7, 1                                              # by hand: d² = 3² + 1² = 10
    assert both[1, r, c].item() == pytest.approx(-10.0 / (2 * 0.5))


def test_irl_goals_follow_the_detached_risk_map_and_change_the_policy():
    g = GRID
    risk = torch.full((1, g.rows, g.cols), -1.0, dtype=torch.float64)
    risk[0, _cell_at(20.0)[0], _cell_at(20.0)[1]] = -9.0
    speed = 10.0
    batch = {"goal_cell": torch.tensor([_cell_at(90.0)]),
             "route_cells": torch.from_numpy(route_cells(_scene(speed), g))[None],
             "motion": torch.full((1, 3, g.rows, g.cols), speed),
             "start_cell": torch.tensor([_cell_at(0.0)]),
             "demo": torch.zeros(1, 2, g.rows, g.cols, dtype=torch.float64),
             "uncertainty": torch.zeros(1, g.rows, g.cols, dtype=torch.float64)}
    plain = IRLConfig(horizon=120)
    held = IRLConfig(horizon=120, risk_goal={"threshold": -6.0})
    cells, variance = goal_cells(risk, batch, plain)
    assert tuple(cells[0].tolist()) == _cell_at(90.0) and variance == plain.goal_variance
    cells, variance = goal_cells(risk, batch, held)
    assert tuple(cells[0].tolist()) == _cell_at(15.0) and variance[0].item() == 0.5
    # the policy's expected visits stop at the held goal: none at 40 m and beyond
    far = slice(0, _cell_at(40.0)[0] + 1)
    assert irl_step(risk, batch, plain).svf[0, far].sum() > 1.0
    assert irl_step(risk, batch, held).svf[0, far].sum() < 1e-3


def test_the_planning_section_overrides_the_training_rule_and_none_means_the_route_rule():
    from riskmap.planner.riskmap_planner import risk_goal_of

    trained = {"irl": {"risk_goal": {"threshold": -7.0}}}
    assert risk_goal_of(trained).threshold == -7.0
    assert risk_goal_of({**trained, "planning": {"risk_goal": {"threshold": -3.0}}}).threshold == -3.0
    assert risk_goal_of({"irl": {"goal_variance": 5.0}, "planning": {}}) is None
    with pytest.raises(InputError, match="risk_goal"):
        risk_goal_of({"planning": {"risk_goal": {"treshold": -6.0}}})


def test_a_model_trained_with_the_rule_plans_with_it(tiny_dataset, tmp_path):
    from riskmap.planner.riskmap_planner import RiskMapPlanner
    from riskmap.training.train import train
    from tests.riskmap.conftest import tiny_train_config

    out = tmp_path / "run"
    train(tiny_train_config(tiny_dataset, out, epochs=1, risk_goal_threshold=-4.0), progress=False)
    planner = RiskMapPlanner.load(out / "last")
    assert planner.risk_goal == RiskGoalConfig(threshold=-4.0)
    with pytest.raises(InputError):
        tiny_train_config(tiny_dataset, out, risk_goal_threshold=float("nan"))
