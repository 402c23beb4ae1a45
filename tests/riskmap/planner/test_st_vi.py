"""Space-time value iteration and visitation against an enumeration of every path (DESIGN §3b, §5)."""

import itertools
import math

import numpy as np
import pytest
import torch

import riskmap.planner.st_vi as st_vi_module
from rasterize.errors import InputError
from riskmap.planner.st_vi import (spacetime_actions, spacetime_log_partition, spacetime_value_iteration,
                                   spacetime_visitation)


@pytest.fixture(params=["numpy", "torch"])
def kernel(request, monkeypatch):
    """Runs a test with both kernels: numpy (CPU, no grad) and torch (run here on the CPU)."""
    if request.param == "torch":
        monkeypatch.setattr(st_vi_module, "use_numpy_kernel", lambda tensor: False)
    return request.param


class PathSums:
    """Brute force over one grid, float64: every path, every step, summed in plain Python.

    reward [T, H, W] holds r_1 … r_T. A path from cell s at step t takes T − t actions; its
    weight is exp(Σ_{u=t+1..T} r_u(s_u) + g(s_T)), and a path that leaves the grid is no path."""

    def __init__(self, reward, goal, max_forward, max_across):
        self.reward, self.goal = reward, goal
        self.horizon, self.h, self.w = reward.shape
        self.actions = [tuple(a) for a in spacetime_actions(max_forward, max_across).tolist()]
        self.memo = {}

    def walk(self, cell, moves):
        """The cells after each move, or None if the path leaves the grid."""
        cells = []
        for a in moves:
            cell = (cell[0] + self.actions[a][0], cell[1] + self.actions[a][1])
            if not (0 <= cell[0] < self.h and 0 <= cell[1] < self.w):
                return None
            cells.append(cell)
        return cells

    def paths(self, t, cell, first=None):
        """(cells s_{t+1} … s_T, log weight) of every path from `cell` at step t."""
        for moves in itertools.product(range(len(self.actions)), repeat=self.horizon - t):
            if first is not None and moves[0] != first:
                continue
            cells = self.walk(cell, moves)
            if cells is None:
                continue
            end = cells[-1] if cells else cell
            yield cells, sum(self.reward[t + i][c] for i, c in enumerate(cells)) + self.goal[end]

    def future(self, t, cell, first=None):
        """log Σ over the paths from `cell` at step t (only those starting with `first`)."""
        key = (t, cell, first)
        if key not in self.memo:
            terms = [log_weight for _, log_weight in self.paths(t, cell, first)]
            top = max(terms, default=-math.inf)
            self.memo[key] = top if not terms else \
                top + math.log(sum(math.exp(x - top) for x in terms))
        return self.memo[key]

    def value(self, t, cell):
        """V_t(s) for t = 1 … T: the step's own reward plus what follows."""
        return self.reward[t - 1][cell] + self.future(t, cell)

    def policy(self, t, cell, a):
        """π_t(a | s): the share of the path sum from s at step t whose first move is a."""
        return math.exp(self.future(t, cell, first=a) - self.future(t, cell))

    def visitation(self, start):
        """D [T, H, W]: the weight share of the paths from `start` that are in s at step t."""
        z = self.future(0, start)
        visits = np.zeros((self.horizon, self.h, self.w))
        for cells, log_weight in self.paths(0, start):
            for i, c in enumerate(cells):
                visits[i][c] += math.exp(log_weight - z)
        return visits


# (H, W, T, max_forward, max_across): forward only one row, a longer forward step than the grid
# is deep at places, a wider sidestep, and no forward move at all.
GRIDS = [(3, 3, 3, 1, 1), (4, 3, 2, 2, 1), (3, 5, 3, 1, 2), (3, 3, 3, 0, 1), (2, 2, 3, 3, 0)]


@pytest.mark.parametrize("grid", GRIDS, ids=[f"{h}x{w}-T{t}-K{k}-M{m}" for h, w, t, k, m in GRIDS])
@pytest.mark.parametrize("seed", [0, 1])
def test_value_policy_visitation_match_path_enumeration(grid, seed, kernel):
    h, w, horizon, max_forward, max_across = grid
    starts = [(0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1), (h // 2, w // 2)]
    rng = np.random.default_rng(seed)
    # One random map per start, so that the batch dimension is checked too.
    reward = rng.normal(-0.5, 1.0, (len(starts), horizon, h, w))
    goal = rng.normal(0.0, 2.0, (len(starts), h, w))
    value, policy = spacetime_value_iteration(torch.tensor(reward), torch.tensor(goal), max_forward,
                                              max_across)
    log_z = spacetime_log_partition(value, torch.tensor(starts), max_forward, max_across)
    visits = spacetime_visitation(policy, torch.tensor(starts), max_forward, max_across)
    n_actions = (max_forward + 1) * (2 * max_across + 1)
    assert value.shape == (len(starts), horizon, h, w) and value.dtype == torch.float64
    assert policy.shape == (len(starts), horizon, n_actions, h, w)
    assert visits.shape == (len(starts), horizon, h, w)
    for b, start in enumerate(starts):
        ref = PathSums(reward[b], goal[b], max_forward, max_across)
        assert log_z[b].item() == pytest.approx(ref.future(0, start), abs=1e-10)
        for t, cell in itertools.product(range(1, horizon + 1), itertools.product(range(h), range(w))):
            assert value[b, t - 1][cell].item() == pytest.approx(ref.value(t, cell), abs=1e-10)
        for t, cell in itertools.product(range(horizon), itertools.product(range(h), range(w))):
            for a in range(n_actions):
                assert policy[b, t, a][cell].item() == pytest.approx(ref.policy(t, cell, a), abs=1e-10)
        np.testing.assert_allclose(visits[b].numpy(), ref.visitation(start), rtol=0, atol=1e-10)


@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-10), (torch.float32, 2e-5)])
def test_numpy_and_torch_kernels_agree_on_planner_sized_maps(dtype, tol):
    """The planner's case, B=2, T=12, 50x50, max_forward=4: the torch kernel (forced by a reward
    that needs a gradient) against the numpy kernel."""
    gen = torch.Generator().manual_seed(7)
    reward = (-3.0 * torch.rand((2, 12, 50, 50), generator=gen) - 0.1).to(dtype)
    reward[0, 3:6, 20:24, 10:40] = -40.0                  # an obstacle passing
    goal = (-5.0 * torch.rand((2, 50, 50), generator=gen)).to(dtype)
    starts = torch.tensor([[45, 25], [49, 0]])
    value_np, policy_np = spacetime_value_iteration(reward, goal, 4)
    log_z_np = spacetime_log_partition(value_np, starts, 4)
    visits_np = spacetime_visitation(policy_np, starts, 4)
    leaf = reward.clone().requires_grad_(True)
    value_t, policy_t = spacetime_value_iteration(leaf, goal, 4)
    log_z_t = spacetime_log_partition(value_t, starts, 4)
    visits_t = spacetime_visitation(policy_t, starts, 4)
    assert value_t.requires_grad and visits_t.requires_grad
    # Relative tolerance on values: V reaches a few hundred, float32 rounds the last digit.
    for ours, theirs in ((value_np, value_t), (log_z_np, log_z_t)):
        torch.testing.assert_close(ours, theirs.detach(), rtol=tol, atol=tol)
    torch.testing.assert_close(policy_np, policy_t.detach(), rtol=0, atol=tol)
    torch.testing.assert_close(visits_np, visits_t.detach(), rtol=0, atol=tol)


def test_gradient_of_the_log_partition_is_the_visitation():
    """∂V_0/∂r_t(s) = D_t(s): autograd through the torch kernel recovers the visitation, which is
    what the IRL loss relies on."""
    gen = torch.Generator().manual_seed(1)
    reward = (-2.0 * torch.rand((2, 5, 7, 6), generator=gen, dtype=torch.float64)).requires_grad_(True)
    goal = torch.randn((2, 7, 6), generator=gen, dtype=torch.float64)
    starts = torch.tensor([[6, 2], [3, 5]])
    value, policy = spacetime_value_iteration(reward, goal, 2)
    spacetime_log_partition(value, starts, 2).sum().backward()
    visits = spacetime_visitation(policy.detach(), starts, 2)
    torch.testing.assert_close(reward.grad, visits, rtol=0, atol=1e-12)


def _on_grid(h, w, max_forward, max_across):
    """[A, H, W] bool: the move stays on the grid."""
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    return np.stack([(rows + dr >= 0) & (cols + dc >= 0) & (cols + dc < w)
                     for dr, dc in spacetime_actions(max_forward, max_across).tolist()])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_policies_are_distributions_without_off_grid_moves(dtype, kernel):
    torch.manual_seed(0)
    b, horizon, h, w, max_forward, max_across = 3, 8, 12, 9, 3, 2
    reward = (-3.0 * torch.rand(b, horizon, h, w)).to(dtype)
    goal = torch.randn(b, h, w).to(dtype)
    value, policy = spacetime_value_iteration(reward, goal, max_forward, max_across)
    on_grid = torch.from_numpy(_on_grid(h, w, max_forward, max_across))
    assert (policy.masked_select(~on_grid) == 0).all()          # exactly 0, not merely small
    stand = spacetime_actions(max_forward, max_across).tolist().index([0, 0])
    assert on_grid[stand].all() and (policy[:, :, stand] > 0).all()
    torch.testing.assert_close(policy.sum(2), torch.ones(b, horizon, h, w, dtype=dtype))
    visits = spacetime_visitation(policy, torch.tensor([[11, 4], [0, 0], [5, 8]]), max_forward,
                                  max_across)
    assert (visits >= 0).all()
    torch.testing.assert_close(visits.sum((2, 3)), torch.ones(b, horizon, dtype=dtype))


def _extreme_cases(dtype, h, w, horizon):
    big = torch.finfo(dtype).max
    gen = torch.Generator().manual_seed(2)
    sign = torch.where(torch.rand((1, horizon, h, w), generator=gen) < 0.5, -1.0, 1.0).to(dtype)
    zeros = torch.zeros((1, horizon, h, w), dtype=dtype)
    flat = torch.zeros((1, h, w), dtype=dtype)
    return {
        "all +1e30": (zeros + 1e30, flat + 1e30),
        "all -1e30": (zeros - 1e30, flat - 1e30),
        "mixed ±1e30": (sign * 1e30, -sign[:, 0] * 1e30),
        "float limits": (sign * big, sign[:, -1] * big),
        "-1e30 goal only": (zeros, flat - 1e30),
        "-1e4 everywhere": (zeros - 1e4, flat - 1e4),
    }


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_no_nan_or_inf_at_the_float_limits(dtype, kernel):
    h, w, horizon, max_forward = 7, 5, 6, 2
    on_grid = torch.from_numpy(_on_grid(h, w, max_forward, 1))
    starts = torch.tensor([[h - 1, 2]])
    for name, (reward, goal) in _extreme_cases(dtype, h, w, horizon).items():
        value, policy = spacetime_value_iteration(reward, goal, max_forward)
        log_z = spacetime_log_partition(value, starts, max_forward)
        visits = spacetime_visitation(policy, starts, max_forward)
        for out in (value, policy, log_z, visits):
            assert torch.isfinite(out).all(), name
        assert (policy.masked_select(~on_grid) == 0).all(), name
        torch.testing.assert_close(policy.sum(2), torch.ones_like(value), msg=name)
        torch.testing.assert_close(visits.sum((2, 3)), torch.ones(1, horizon, dtype=dtype), msg=name)


def test_waiting_for_an_obstacle_to_pass(kernel):
    """A corridor one cell wide: start at the back (row 5), the goal at the front (row 0), up to
    two rows a step and exactly four steps. Rows 2-3 are taken at steps 1 and 2 only, and two
    rows are deeper than one move, so the obstacle cannot be jumped. Reaching the goal on time
    then needs standing still behind the obstacle and crossing as it leaves: "free now, taken in
    a second" is a reward the space-time planner can answer."""
    h, horizon, max_forward = 6, 4, 2
    reward = torch.zeros((1, horizon, h, 1), dtype=torch.float64)
    reward[0, 0:2, 2:4] = -50.0                            # steps 1 and 2, rows 2 and 3
    goal = torch.full((1, h, 1), -20.0, dtype=torch.float64)
    goal[0, 0] = 0.0
    start = torch.tensor([[5, 0]])
    _, policy = spacetime_value_iteration(reward, goal, max_forward, max_across=0)
    visits = spacetime_visitation(policy, start, max_forward, max_across=0)[0, :, :, 0]
    assert visits[0:2, 2:4].sum() < 1e-12                  # nothing on the obstacle while it is there
    assert visits[1, 4] > 0.99                             # waiting behind it at step 2
    assert visits[2, 2] > 0.99                             # crossing right after it leaves
    assert visits[3, 0] > 0.99                             # and on the goal in time
    # The same obstacle staying put keeps the goal out of reach: it is the timing that helps.
    reward[0, :, 2:4] = -50.0
    _, policy = spacetime_value_iteration(reward, goal, max_forward, max_across=0)
    visits = spacetime_visitation(policy, start, max_forward, max_across=0)[0, :, :, 0]
    assert visits[3, 0] < 1e-6


def test_bad_inputs_are_named(kernel):
    zeros = torch.zeros(1, 3, 4, 4)
    with pytest.raises(ValueError, match="finite"):
        spacetime_value_iteration(torch.full((1, 3, 4, 4), float("nan")), torch.zeros(1, 4, 4), 1)
    with pytest.raises(ValueError, match="finite"):
        spacetime_value_iteration(zeros, torch.full((1, 4, 4), float("inf")), 1)
    with pytest.raises(ValueError, match=r"\[B, T, H, W\]"):
        spacetime_value_iteration(torch.zeros(3, 4, 4), torch.zeros(1, 4, 4), 1)
    with pytest.raises(ValueError, match=r"\[B, T, H, W\]"):
        spacetime_value_iteration(zeros, torch.zeros(1, 4, 5), 1)
    with pytest.raises(ValueError, match=r"T >= 1"):
        spacetime_value_iteration(torch.zeros(1, 0, 4, 4), torch.zeros(1, 4, 4), 1)
    with pytest.raises(InputError, match="max_forward"):
        spacetime_value_iteration(zeros, torch.zeros(1, 4, 4), -1)
    with pytest.raises(InputError, match="max_across"):
        spacetime_value_iteration(zeros, torch.zeros(1, 4, 4), 1, max_across=-2)
    value, policy = spacetime_value_iteration(zeros, torch.zeros(1, 4, 4), 1)
    for bad in ([[4, 0]], [[0, -1]], [[2, 4]]):
        with pytest.raises(ValueError, match="outside the 4x4 grid"):
            spacetime_visitation(policy, torch.tensor(bad), 1)
        with pytest.raises(ValueError, match="outside the 4x4 grid"):
            spacetime_log_partition(value, torch.tensor(bad), 1)
    with pytest.raises(ValueError, match=r"\[B, 2\]"):
        spacetime_visitation(policy, torch.tensor([1, 1]), 1)
    with pytest.raises(ValueError, match="policy must be"):
        spacetime_visitation(policy, torch.tensor([[1, 1]]), 2)      # built for another action set


def test_action_set_order_and_validation():
    np.testing.assert_array_equal(spacetime_actions(2, 1), [[0, -1], [0, 0], [0, 1], [-1, -1], [-1, 0],
                                                            [-1, 1], [-2, -1], [-2, 0], [-2, 1]])
    np.testing.assert_array_equal(spacetime_actions(0, 0), [[0, 0]])
    np.testing.assert_array_equal(spacetime_actions(1, 0), [[0, 0], [-1, 0]])
    np.testing.assert_array_equal(spacetime_actions(0, 2), [[0, -2], [0, -1], [0, 0], [0, 1], [0, 2]])
    actions = spacetime_actions(4)
    assert actions.shape == (15, 2) and actions.dtype == np.int64
    np.testing.assert_array_equal(actions, spacetime_actions(np.int64(4), 1))
    assert actions.tolist().index([0, 0]) == 1                      # standing still is at max_across
    for bad, name in (((-1, 1), "max_forward"), ((1, -1), "max_across"), ((1.5, 1), "max_forward"),
                      ((2, True), "max_across")):
        with pytest.raises(InputError, match=name):
            spacetime_actions(*bad)
