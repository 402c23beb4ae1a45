"""Properties of soft value iteration and state visitation (riskmap/planner/vi.py) for any finite
reward and goal maps: huge magnitudes, ties, one outlier cell, tiny and planner-like grids, both
kernels and both float widths. The float64 references live in tests/riskmap/planner/test_vi.py;
here only what must hold whatever the input."""

import itertools
from contextlib import contextmanager
from unittest import mock

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import riskmap.planner.vi as vi_module
from riskmap.planner.vi import MOVES, soft_value_iteration, state_visitation

KERNELS = ("numpy", "torch")
DTYPES = (torch.float32, torch.float64)
PROPERTY = settings(max_examples=50, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow])


@contextmanager
def kernel(name):
    """The torch kernel is what other devices run; forcing it here checks it on the CPU."""
    if name == "numpy":
        yield
    else:
        with mock.patch.object(vi_module, "use_numpy_kernel", lambda tensor: False):
            yield


def _magnitudes(dtype):
    """Finite values of every size the dtype holds, with the usual suspects made likely."""
    big = float(torch.finfo(dtype).max)
    special = [0.0, 1.0, -1.0, 1e7, -1e7, 1e20, -1e20, 1e30, -1e30, 3e38, -3e38, big, -big]
    return st.one_of(st.sampled_from(special),
                     st.floats(-50.0, 50.0),
                     st.floats(-big, big, allow_nan=False, allow_infinity=False,
                               width=32 if dtype == torch.float32 else 64))


@st.composite
def maps(draw, dtype):
    """(reward, goal) [B, H, W], each of one of four kinds: all one value, one cell different,
    uniform noise of a drawn scale, or (on small grids) every cell drawn on its own."""
    b = draw(st.integers(1, 2))
    h, w = draw(st.sampled_from([(1, 1), (1, 5), (5, 1), (2, 2), (3, 4), (8, 8), (17, 30), (30, 30)]))
    value = _magnitudes(dtype)
    out = []
    for _ in range(2):
        kind = draw(st.sampled_from(["constant", "outlier", "random", "cells"]))
        if kind == "cells" and h * w <= 16:
            grid = np.array(draw(st.lists(value, min_size=b * h * w, max_size=b * h * w)))
        elif kind == "random":
            seed, scale = draw(st.integers(0, 2**16)), abs(draw(value))
            grid = scale * np.random.default_rng(seed).uniform(-1.0, 1.0, b * h * w)
        else:
            grid = np.full(b * h * w, draw(value))
            if kind == "outlier":
                grid[draw(st.integers(0, b * h * w - 1))] = draw(value)
        out.append(torch.tensor(grid.reshape(b, h, w), dtype=dtype))
    # scale x uniform(-1, 1) never leaves the dtype's range
    assert all(torch.isfinite(m).all() for m in out)
    return out


def _off_grid(h, w):
    """Mask [5, H, W] of the moves that would leave the grid."""
    mask = np.zeros((5, h, w), bool)
    for a, (dr, dc) in MOVES.items():
        rows, cols = np.meshgrid(np.arange(h) + dr, np.arange(w) + dc, indexing="ij")
        mask[a] = (rows < 0) | (rows >= h) | (cols < 0) | (cols >= w)
    return mask


def _check_policy(policy, shape, dtype):
    b, h, w = shape
    assert policy.shape == (b, 5, h, w) and policy.dtype == dtype
    assert torch.isfinite(policy).all()
    assert (policy >= 0).all() and (policy <= 1).all()
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    np.testing.assert_allclose(policy.sum(1).double().numpy(), 1.0, rtol=0, atol=tol)
    # "Moves off the grid do not exist" (module docstring).
    assert (policy.numpy()[:, _off_grid(h, w)] == 0).all()


def _per_step_mass(policy, starts, horizon):
    """Mass on the path layer at each step [horizon, B, H, W], from consecutive visit counts."""
    counts = [torch.zeros(policy.shape[0], *policy.shape[2:], dtype=policy.dtype)]
    counts += [state_visitation(policy, starts, n)[0] for n in range(1, horizon + 1)]
    return torch.stack([b - a for a, b in itertools.pairwise(counts)])


@pytest.mark.parametrize("name", KERNELS)
@pytest.mark.parametrize("dtype", DTYPES)
@PROPERTY
@given(data=st.data(), horizon=st.integers(1, 12), gamma=st.sampled_from([1.0, 0.99, 0.9, 0.5]))
def test_policy_is_a_distribution_over_moves_that_exist(name, dtype, data, horizon, gamma):
    reward, goal = data.draw(maps(dtype))
    with kernel(name):
        value, policy = soft_value_iteration(reward, goal, horizon, gamma)
    assert not torch.isnan(value).any()
    _check_policy(policy, reward.shape, dtype)


@pytest.mark.parametrize("name", KERNELS)
@pytest.mark.parametrize("dtype", DTYPES)
@PROPERTY
@given(data=st.data(), horizon=st.integers(1, 10), gamma=st.sampled_from([1.0, 0.95]))
def test_visitation_is_probability_mass(name, dtype, data, horizon, gamma):
    reward, goal = data.draw(maps(dtype))
    b, h, w = reward.shape
    starts = torch.tensor(data.draw(st.lists(st.tuples(st.integers(0, h - 1), st.integers(0, w - 1)),
                                             min_size=b, max_size=b)))
    with kernel(name):
        _, policy = soft_value_iteration(reward, goal, horizon, gamma)
        svf, svf_goal = state_visitation(policy, starts, horizon)
        mass = _per_step_mass(policy, starts, horizon)
    tol = 1e-4 if dtype == torch.float32 else 1e-10
    for t in (svf, svf_goal, mass):
        assert torch.isfinite(t).all() and (t >= -tol).all()
    assert (mass <= 1 + tol).all()
    assert (mass.sum((2, 3)) <= 1 + tol).all()                 # per step and grid
    assert (svf <= horizon + tol).all()
    # Nothing leaves the grid: what has not ended is still on the path layer.
    with kernel(name):
        still_moving = state_visitation(policy, starts, horizon + 1)[0] - svf
    total = (svf_goal.sum((1, 2)) + still_moving.sum((1, 2))).double().numpy()
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=tol)


@pytest.mark.parametrize("name", KERNELS)
@pytest.mark.parametrize("dtype", DTYPES)
@PROPERTY
@given(data=st.data(), horizon=st.integers(1, 12), gamma=st.sampled_from([1.0, 0.9]))
def test_the_two_kernels_agree_on_moderate_maps(name, dtype, data, horizon, gamma):
    """Where nothing saturates, the numpy and torch kernels compute the same policy."""
    h, w = data.draw(st.sampled_from([(1, 1), (1, 4), (2, 2), (5, 7)]))
    reward, goal = (torch.tensor(data.draw(st.lists(st.floats(-20.0, 20.0), min_size=h * w,
                                                    max_size=h * w)), dtype=dtype).reshape(1, h, w)
                    for _ in range(2))
    with kernel(name):
        value, policy = soft_value_iteration(reward, goal, horizon, gamma)
    with kernel("torch" if name == "numpy" else "numpy"):
        other_value, other_policy = soft_value_iteration(reward, goal, horizon, gamma)
    tol = 1e-4 if dtype == torch.float32 else 1e-10
    np.testing.assert_allclose(policy.numpy(), other_policy.numpy(), rtol=0, atol=tol)
    np.testing.assert_allclose(value.numpy(), other_value.numpy(), rtol=tol, atol=tol)


# Found by the properties above. The policy was exp(Q − V) with V = logsumexp Q: where several
# options tie at a large |V|, the log of their count (≤ ln 5) is lost in V's rounding and each
# tied option got probability 1 (rows summing to up to 5, the mass growing each step). And where
# clamping ties the real options with the −∞ stand-in (goal ≤ −1e30, or the torch kernel's
# rewards ≥ 1e30), moves off the grid got mass, which then vanished.
@pytest.mark.parametrize("name", KERNELS)
@pytest.mark.parametrize("dtype,reward,goal,horizon,start", [
    (torch.float32, [[0.0]], [[-1e30]], 1, (0, 0)),            # 1x1: the only real option, end
    (torch.float64, [[0.0] * 5], [[-3e38] * 5], 3, (0, 0)),
    (torch.float32, [[0.0] * 5], [[1e7] * 5], 4, (0, 1)),      # moves and end tie at 1e7
    (torch.float64, [[0.0] * 5], [[1e20] * 5], 3, (0, 1)),
    (torch.float32, [[1e16] * 3] * 3, [[0.0] * 3] * 3, 5, (1, 1)),   # 4 moves tie
    (torch.float32, [[3e38] * 3] * 3, [[3e38] * 3] * 3, 5, (2, 0)),  # everything clamped
])
def test_tied_or_saturated_options_keep_the_policy_a_distribution(name, dtype, reward, goal, horizon,
                                                                  start):
    reward, goal = torch.tensor([reward], dtype=dtype), torch.tensor([goal], dtype=dtype)
    with kernel(name):
        _, policy = soft_value_iteration(reward, goal, horizon)
        _check_policy(policy, reward.shape, dtype)
        starts = torch.tensor([start])
        mass = _per_step_mass(policy, starts, horizon + 1)
        svf_goal = state_visitation(policy, starts, horizon)[1]
    assert (mass.sum((2, 3)) <= 1 + 1e-6).all()
    np.testing.assert_allclose((svf_goal.sum() + mass[-1].sum()).item(), 1.0, atol=1e-6)
    if reward.shape[1:] == (1, 1):
        np.testing.assert_array_equal(policy.numpy().ravel(), [0, 0, 0, 0, 1])
