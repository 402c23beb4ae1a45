import numpy as np
import torch

from rasterize.config import Extent, GridConfig
from riskmap.sampler import SamplerConfig, sample_paths, sample_trajectory
from riskmap.vi import soft_value_iteration, state_visitation

GRID = GridConfig(Extent(10.0, 10.0, 10.0, 10.0), rows=20, cols=20)


def _policy(goal_cell=(2, 10)):
    reward = torch.full((1, 20, 20), -2.0, dtype=torch.float64)
    goal = torch.full((1, 20, 20), -100.0, dtype=torch.float64)
    goal[0, goal_cell[0], goal_cell[1]] = 0.0
    return soft_value_iteration(reward, goal, horizon=30)[1][0]


def test_sample_paths_follow_the_grid_and_match_the_svf():
    policy = _policy()
    paths, lengths = sample_paths(policy, (15, 10), 30, 4000, torch.Generator().manual_seed(0))
    steps = (paths[:, 1:] - paths[:, :-1]).abs().sum(-1)
    assert steps.max() <= 1                                   # one 4-neighbour move at a time
    assert ((paths >= 0) & (paths < 20)).all()
    # The empirical end distribution matches the analytic svf_goal.
    _, svf_goal = state_visitation(policy[None], torch.tensor([[15, 10]]), 30)
    ends = paths[torch.arange(len(paths)), lengths]
    hit = ((ends[:, 0] == 2) & (ends[:, 1] == 10)).double().mean()
    assert abs(hit.item() - svf_goal[0, 2, 10].item()) < 0.03


def test_trajectory_goes_to_the_goal_and_is_deterministic():
    policy = _policy()
    a = sample_trajectory(policy, (15, 10), 30, GRID, SamplerConfig(samples=1000), seed=3)
    b = sample_trajectory(policy, (15, 10), 30, GRID, SamplerConfig(samples=1000), seed=3)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (12, 2)
    # Goal cell (2, 10) has its centre at x = 7.5, y = -0.5; start (15, 10) at x = -5.5.
    np.testing.assert_allclose(a[-1], [7.5, -0.5])
    assert np.all(np.diff(a[:, 0]) >= 0)                     # straight up, never back
