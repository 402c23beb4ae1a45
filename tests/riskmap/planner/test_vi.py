"""Soft value iteration and state visitation against plain float64 references (DESIGN §3, §5)."""

import itertools
import math

import numpy as np
import pytest
import torch

import riskmap.planner.vi as vi_module
from riskmap.planner.vi import ACTIONS, END, MOVES, soft_value_iteration, state_visitation


@pytest.fixture(autouse=True, params=["numpy", "torch"])
def kernel(request, monkeypatch):
    """Every test runs both kernels: numpy (CPU) and torch (other devices, run here on the CPU)."""
    if request.param == "torch":
        monkeypatch.setattr(vi_module, "use_numpy_kernel", lambda tensor: False)
    return request.param


def _next(cell, action, h, w):
    dr, dc = MOVES[action]
    r, c = cell[0] + dr, cell[1] + dc
    return (r, c) if 0 <= r < h and 0 <= c < w else None


def brute_force_value(reward, goal, n, gamma, cell):
    """log Σ over all paths from `cell` with at most n-1 moves, then end, of exp(return)."""
    h, w = reward.shape
    terms = []
    for k in range(n):
        for moves in itertools.product(range(4), repeat=k):
            pos, ret, ok = cell, 0.0, True
            for i, a in enumerate(moves):
                ret += gamma ** i * reward[pos]
                pos = _next(pos, a, h, w)
                if pos is None:
                    ok = False
                    break
            if ok:
                terms.append(ret + gamma ** k * (reward[pos] + gamma * goal[pos]))
    m = max(terms)
    return m + math.log(sum(math.exp(t - m) for t in terms))


# The path-sum reading of V holds for gamma = 1 (with gamma < 1 the soft backup discounts the
# log-sum, not each path); the loop reference below covers gamma < 1.
@pytest.mark.parametrize("size,horizon,gamma", [(3, 4, 1.0), (3, 5, 1.0), (4, 5, 1.0)])
def test_value_and_policy_match_path_enumeration(size, horizon, gamma):
    rng = np.random.default_rng(size * 10 + horizon)
    reward = -rng.uniform(0.0, 2.0, (size, size))
    goal = rng.normal(0.0, 1.0, (size, size))
    value, policy = soft_value_iteration(torch.tensor(reward)[None], torch.tensor(goal)[None],
                                         horizon, gamma)
    for cell in itertools.product(range(size), repeat=2):
        ref = brute_force_value(reward, goal, horizon, gamma, cell)
        assert value[0][cell].item() == pytest.approx(ref, abs=1e-9)
        # π(a|s) = exp(Q^N(s,a) − V^N(s)), Q from the (N−1)-step enumeration of the next cell.
        for a in range(5):
            if a == END:
                q = reward[cell] + gamma * goal[cell]
            else:
                nxt = _next(cell, a, size, size)
                if nxt is None:
                    assert policy[0, a][cell].item() == 0.0
                    continue
                q = reward[cell] + gamma * brute_force_value(reward, goal, horizon - 1, gamma, nxt) \
                    if horizon > 1 else -math.inf
            assert policy[0, a][cell].item() == pytest.approx(math.exp(q - ref), abs=1e-9)


def loop_reference(reward, goal, horizon, gamma, start):
    """Plain Python loops, float64: value, policy, svf_path, svf_goal of one grid."""
    h, w = reward.shape
    v = np.full((h, w), -np.inf)
    q = np.zeros((5, h, w))
    for _ in range(horizon):
        q = np.full((5, h, w), -np.inf)
        for r in range(h):
            for c in range(w):
                for a in range(4):
                    nxt = _next((r, c), a, h, w)
                    if nxt is not None:
                        q[a, r, c] = reward[r, c] + gamma * v[nxt]
                q[END, r, c] = reward[r, c] + gamma * goal[r, c]
        m = q.max(axis=0)
        v = m + np.log(np.exp(q - m).sum(axis=0))
    pi = np.exp(q - v)
    mass = np.zeros((h, w))
    mass[start] = 1.0
    svf, svf_goal = np.zeros((h, w)), np.zeros((h, w))
    for _ in range(horizon):
        svf += mass
        nxt_mass = np.zeros((h, w))
        for r in range(h):
            for c in range(w):
                svf_goal[r, c] += mass[r, c] * pi[END, r, c]
                for a in range(4):
                    nxt = _next((r, c), a, h, w)
                    if nxt is not None:
                        nxt_mass[nxt] += mass[r, c] * pi[a, r, c]
        mass = nxt_mass
    return v, pi, svf, svf_goal


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_implementation_matches_loops_on_random_8x8(seed):
    rng = np.random.default_rng(seed)
    batch, h, w, horizon, gamma = 3, 8, 8, 12, [1.0, 0.99, 0.9][seed]
    reward = -rng.exponential(1.0, (batch, h, w))
    goal = rng.normal(0, 2, (batch, h, w))
    starts = rng.integers(0, 8, (batch, 2))
    value, policy = soft_value_iteration(torch.tensor(reward), torch.tensor(goal), horizon, gamma)
    svf, svf_goal = state_visitation(policy, torch.tensor(starts), horizon)
    for b in range(batch):
        v, pi, s, sg = loop_reference(reward[b], goal[b], horizon, gamma, tuple(starts[b]))
        np.testing.assert_allclose(value[b].numpy(), v, atol=1e-9)
        np.testing.assert_allclose(policy[b].numpy(), pi, atol=1e-9)
        np.testing.assert_allclose(svf[b].numpy(), s, atol=1e-9)
        np.testing.assert_allclose(svf_goal[b].numpy(), sg, atol=1e-9)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_mass_is_conserved_and_policies_are_distributions(dtype):
    torch.manual_seed(0)
    reward = -torch.rand(4, 25, 25, dtype=dtype) * 3
    goal = torch.randn(4, 25, 25, dtype=dtype)
    horizon = 30
    _, policy = soft_value_iteration(reward, goal, horizon)
    torch.testing.assert_close(policy.sum(1), torch.ones(4, 25, 25, dtype=dtype))
    starts = torch.tensor([[24, 12], [0, 0], [12, 12], [5, 20]])
    svf, svf_goal = state_visitation(policy, starts, horizon)
    # After N steps: Σ svf_goal + the mass still on the path layer = 1.
    still_moving = state_visitation(policy, starts, horizon + 1)[0] - svf
    total = svf_goal.sum((1, 2)) + still_moving.sum((1, 2))
    torch.testing.assert_close(total, torch.ones(4, dtype=dtype))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_no_nan_at_the_float_limits(dtype):
    big = torch.finfo(dtype).max
    h = w = 6
    cases = [
        (torch.full((1, h, w), -big / 2, dtype=dtype), torch.zeros(1, h, w, dtype=dtype)),
        (torch.full((1, h, w), -big, dtype=dtype), torch.full((1, h, w), -big, dtype=dtype)),
        (torch.full((1, h, w), big, dtype=dtype), torch.full((1, h, w), big, dtype=dtype)),
        (torch.zeros(1, h, w, dtype=dtype), torch.full((1, h, w), -big, dtype=dtype)),
    ]
    # A goal far out of reach: only one corner is rewarding, the horizon is too short to get there.
    far = torch.full((1, 20, 20), -50.0, dtype=dtype)
    far[0, 0, 0] = 50.0
    cases.append((torch.zeros(1, 20, 20, dtype=dtype), far))
    for reward, goal in cases:
        value, policy = soft_value_iteration(reward, goal, horizon=5)
        svf, svf_goal = state_visitation(policy, torch.tensor([[reward.shape[1] - 1, 0]]), 5)
        for t in (value, policy, svf, svf_goal):
            assert not torch.isnan(t).any()
        assert torch.isfinite(policy).all() and torch.isfinite(svf).all()


def test_end_pulls_towards_the_goal():
    # Each step costs 2, so wandering (4 e^-2 < 1) does not pay; ending off the goal costs 100.
    reward = torch.full((1, 9, 9), -2.0, dtype=torch.float64)
    goal = torch.full((1, 9, 9), -100.0, dtype=torch.float64)
    goal[0, 0, 4] = 0.0                                   # goal straight ahead at the top
    _, policy = soft_value_iteration(reward, goal, horizon=20)
    svf, svf_goal = state_visitation(policy, torch.tensor([[8, 4]]), 20)
    assert svf_goal[0, 0, 4] > 0.95
    up, left = policy[0, ACTIONS.index("up"), 8, 4], policy[0, ACTIONS.index("left"), 8, 4]
    assert up > 0.7 and up > 5 * left


def test_bad_inputs_are_named():
    with pytest.raises(ValueError, match="finite"):
        soft_value_iteration(torch.full((1, 3, 3), float("nan")), torch.zeros(1, 3, 3), 3)
    with pytest.raises(ValueError, match=r"\[B, H, W\]"):
        soft_value_iteration(torch.zeros(3, 3), torch.zeros(3, 3), 3)
    _, policy = soft_value_iteration(torch.zeros(1, 3, 3), torch.zeros(1, 3, 3), 3)
    with pytest.raises(ValueError, match="outside"):
        state_visitation(policy, torch.tensor([[3, 0]]), 3)


@pytest.mark.parametrize("gamma", [1.0, 0.95])
def test_the_two_kernels_agree_on_planner_sized_float32_maps(gamma, monkeypatch):
    """The planner's case: float32, 50x50, horizon 80; values and policies of the numpy kernel
    against the torch kernel (float32 rounding differs by the order of the additions only)."""
    gen = torch.Generator().manual_seed(3)
    reward = -4.0 * torch.rand((2, 50, 50), generator=gen) - 0.2
    goal = -0.1 * torch.rand((2, 50, 50), generator=gen)
    starts = torch.tensor([[45, 25], [49, 0]])
    with monkeypatch.context() as m:
        m.setattr(vi_module, "use_numpy_kernel", lambda tensor: False)
        v_torch, p_torch = soft_value_iteration(reward, goal, 80, gamma)
        s_torch = state_visitation(p_torch, starts, 80)
    m.undo()
    v_np, p_np = vi_module._value_iteration_numpy(reward.numpy(), goal.numpy(), 80, gamma)
    s_np = vi_module._state_visitation_numpy(p_np, starts.numpy(), 80)
    np.testing.assert_allclose(v_np, v_torch.numpy(), rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(p_np, p_torch.numpy(), atol=2e-5)
    for a, b in zip(s_np, s_torch, strict=True):
        np.testing.assert_allclose(a, b.numpy(), rtol=1e-5, atol=2e-5)
