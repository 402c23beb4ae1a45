import numpy as np
import torch

from rasterize.config import Extent, GridConfig
from riskmap.planner.sampler import SamplerConfig, sample_paths, sample_trajectory
from riskmap.planner.vi import soft_value_iteration, state_visitation

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


def test_waypoints_are_evenly_spaced_in_metres_on_non_square_cells():
    from riskmap.planner.sampler import downsample

    grid = GridConfig(Extent(200.0, 40.0, 20.0, 20.0), rows=50, cols=50)   # 4.8 m x 0.8 m cells
    # 10 moves up, then 5 moves left: 48 m forward and 4 m sideways.
    cells = [(40, 25)] + [(40 - k, 25) for k in range(1, 11)] + [(30, 25 - k) for k in range(1, 6)]
    paths = np.array(cells)[None]
    wp = downsample(paths, np.array([15]), 12, grid)[0]
    x0, y0 = grid.extent.front_m - 40.5 * 4.8, grid.extent.left_m - 25.5 * 0.8   # start centre
    s = 52.0 * np.arange(1, 13) / 12                      # equal arc-length steps of 4.33 m
    expected = np.stack([x0 + np.minimum(s, 48.0), y0 + np.maximum(s - 48.0, 0.0)], axis=1)
    np.testing.assert_allclose(wp, expected, atol=1e-9)


def test_kinematic_timing_against_hand_computed_profiles():
    from riskmap.planner.sampler import kinematic_arc_lengths

    t = 0.5 * np.arange(1, 13)
    # 10 m/s over a 72 m path in 6 s: a = 2 (72 - 60) / 36 = 2/3 m/s².
    np.testing.assert_allclose(kinematic_arc_lengths(72.0, 10.0, t, 3.0), 10 * t + t ** 2 / 3, atol=1e-12)
    # Standing still, 90 m ahead: a would be 5 m/s², capped at 3, so the path is not finished.
    np.testing.assert_allclose(kinematic_arc_lengths(90.0, 0.0, t, 3.0), 1.5 * t ** 2, atol=1e-12)
    # 10 m/s and only 20 m: brake uniformly to stop at 20 m (at t = 4 s), then stay.
    s = kinematic_arc_lengths(20.0, 10.0, t, 3.0)
    np.testing.assert_allclose(s, np.where(t < 4.0, 10 * t - 100 * t ** 2 / 80, 20.0), atol=1e-12)
    assert np.all(np.diff(s) >= 0) and s[-1] == 20.0
    assert not kinematic_arc_lengths(0.0, 5.0, t, 3.0).any()


def test_kinematic_waypoints_keep_the_path_and_the_current_speed():
    policy = _policy()
    uniform = sample_trajectory(policy, (15, 10), 30, GRID, SamplerConfig(timing="uniform"), seed=3)
    fast = sample_trajectory(policy, (15, 10), 30, GRID, SamplerConfig(), seed=3, speed_mps=3.0)
    # Same path (13 m straight ahead), same end; from 3 m/s, slowing at a = 2 (13 - 18) / 36 to
    # end there at 6 s, where uniform spacing would move 13/12 m every step.
    np.testing.assert_allclose(fast[-1], uniform[-1])
    np.testing.assert_allclose(fast[:, 1], -0.5)
    accel = 2 * (13.0 - 18.0) / 36.0
    np.testing.assert_allclose(fast[0, 0] - (-5.5), 3.0 * 0.5 + 0.5 * accel * 0.25, atol=1e-9)
    # No speed given: uniform whatever the setting.
    np.testing.assert_array_equal(sample_trajectory(policy, (15, 10), 30, GRID, SamplerConfig(), seed=3),
                                  uniform)


def test_kinematic_waypoints_start_at_the_ego_not_at_its_cell_centre():
    from riskmap.planner.sampler import retime

    grid = GridConfig(Extent(150.0, 30.0, 15.0, 15.0), rows=50, cols=50)   # US-101: 3.6 x 0.6 m
    start = np.array([[41, 25]])                     # the ego's cell; its centre is 0.6 m ahead
    stay = retime(start, 0, grid, 0.0, SamplerConfig())
    np.testing.assert_array_equal(stay, np.zeros((12, 2)))     # a standing plan does not creep
    ahead = retime(np.array([[41, 25], [40, 25], [39, 25]]), 2, grid, 0.0, SamplerConfig())
    # From the ego to the next cell's centre (4.2 m on, 0.3 m right), one cell more: reached at
    # 6 s from standstill with a = 2 L / 36.
    first = np.hypot(4.2, 0.3)
    accel = 2 * (first + 3.6) / 36
    np.testing.assert_allclose(ahead[-1], [7.8, -0.3], atol=1e-9)
    np.testing.assert_allclose(ahead[0], 0.5 * accel * 0.25 * np.array([4.2, -0.3]) / first, atol=1e-9)


def test_a_path_into_the_goal_cell_ends_at_the_goal_itself():
    from riskmap.planner.sampler import retime

    grid = GridConfig(Extent(150.0, 30.0, 15.0, 15.0), rows=50, cols=50)
    path = np.array([[41, 25], [40, 25], [39, 25]])
    goal = np.array([8.9, -0.1])                   # inside cell (39, 25), whose centre is (7.8, -0.3)
    end = retime(path, 2, grid, 0.0, SamplerConfig(), goal_xy=goal)
    np.testing.assert_allclose(end[-1], goal, atol=1e-9)
    elsewhere = retime(path, 2, grid, 0.0, SamplerConfig(), goal_xy=np.array([20.0, 0.0]))
    np.testing.assert_allclose(elsewhere[-1], [7.8, -0.3], atol=1e-9)   # not the goal's cell


def _loop_walk(policy: np.ndarray, start, horizon: int, uniforms: np.ndarray):
    """Plain reference of the inverse-CDF walk: per path and step, the first action whose
    cumulative probability exceeds the draw; `end` (or the horizon) stops the path."""
    from riskmap.planner.vi import END, MOVES

    paths, lengths = [], []
    for s in range(uniforms.shape[1]):
        cell, path = tuple(start), [tuple(start)]
        for t in range(horizon):
            cumulative = np.cumsum(policy[:, cell[0], cell[1]])
            action = next((a for a in range(END) if uniforms[t, s] < cumulative[a]), END)
            if action == END:
                break
            cell = (cell[0] + MOVES[action][0], cell[1] + MOVES[action][1])
            path.append(cell)
        lengths.append(len(path) - 1)
        paths.append(path + [cell] * (horizon + 1 - len(path)))
    return np.array(paths), np.array(lengths)


def test_the_vectorised_walk_equals_a_plain_loop_with_the_same_draws():
    rng = np.random.default_rng(4)
    reward = torch.tensor(-rng.uniform(0.2, 2.0, (1, 12, 12)))
    goal = torch.tensor(rng.normal(0.0, 3.0, (1, 12, 12)))
    policy = soft_value_iteration(reward, goal, horizon=15)[1][0]
    paths, lengths = sample_paths(policy, (10, 6), 15, 300, torch.Generator().manual_seed(9))
    uniforms = torch.rand((15, 300, 1), generator=torch.Generator().manual_seed(9),
                          dtype=torch.float64).numpy()[..., 0]
    ref_paths, ref_lengths = _loop_walk(policy.numpy(), (10, 6), 15, uniforms)
    np.testing.assert_array_equal(lengths.numpy(), ref_lengths)
    np.testing.assert_array_equal(paths.numpy(), ref_paths)
    assert 0 < ref_lengths.min() < ref_lengths.max()          # paths of several lengths


def test_kmeans_finds_separated_clusters_and_is_deterministic():
    from riskmap.planner.sampler import kmeans

    rng = np.random.default_rng(0)
    centres = rng.uniform(-50, 50, (5, 24))
    truth = rng.integers(0, 5, 600)
    points = centres[truth] + rng.normal(0, 0.5, (600, 24))
    labels = kmeans(points, 5, seed=1)
    np.testing.assert_array_equal(labels, kmeans(points, 5, seed=1))
    # The same partition up to renaming: every true cluster maps to exactly one label.
    pairs = set(zip(truth.tolist(), labels.tolist()))
    assert len(pairs) == 5 and len({t for t, _ in pairs}) == 5 and len({lab for _, lab in pairs}) == 5


def test_kmeans_with_as_many_clusters_as_distinct_points_separates_them_all():
    from riskmap.planner.sampler import kmeans

    points = np.repeat(np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]]), [50, 30, 20], axis=0)
    labels = kmeans(points, 3, seed=0)
    assert sorted(np.bincount(labels).tolist()) == [20, 30, 50]


def test_distinct_at_least_counts_exactly_below_k():
    from riskmap.planner.sampler import distinct_at_least

    rows = np.repeat(np.arange(12.0).reshape(4, 3), 25, axis=0)           # 4 distinct rows
    assert distinct_at_least(rows, 10) == 4
    assert distinct_at_least(rows, 3) == 3
    many = np.random.default_rng(0).normal(size=(100, 6))
    assert distinct_at_least(many, 10) == 10
    # Rows that one projection could confuse are still told apart exactly.
    assert distinct_at_least(np.array([[1.0, 0.0], [0.0, 1.0]] * 5), 10) == 2
