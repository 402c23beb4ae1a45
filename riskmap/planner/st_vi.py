"""Space-time soft value iteration and state visitation: the planner that can wait (DESIGN §3b).

Shapes: reward [B, T, H, W] holds r_1 … r_T; goal [B, H, W] is g (a log-space terminal reward);
value [B, T, H, W] holds V_1 … V_T; policy [B, T, A, H, W] holds π_0 … π_{T−1} over the actions
of `spacetime_actions`; visitation [B, T, H, W] holds D_1 … D_T; start_cells [B, 2] (row, col).
Row 0 is the front of the grid, so row − 1 is forward. An action a = (d_row, d_col) moves a cell
s to next(s, a) = (row + d_row, col + d_col); moves that leave the grid do not exist, and
standing still (0, 0) always does, so every cell has a successor and every path has T steps.

    V_T(s)     = r_T(s) + g(s)
    V_t(s)     = r_t(s) + logsumexp_{a: next(s,a) on grid} V_{t+1}(next(s, a))      t = T−1 … 1
    V_0(s₀)    = logsumexp_a V_1(next(s₀, a))                                      (log partition)
    π_t(a | s) = exp(V_{t+1}(next(s, a)) − logsumexp_{a'} V_{t+1}(next(s, a')))      t = 0 … T−1
    D_0 = one-hot(s₀);  D_{t+1}(s') = Σ_s Σ_a D_t(s) π_t(a | s) [next(s, a) = s']

So V_0(s₀) = log Σ_paths exp(Σ_t r_t(s_t) + g(s_T)) and D_t(s) is the probability of being in s
at step t. No discount.

As in `riskmap.planner.vi`, no NaN or inf ever leaves: values are clamped into [neg, −neg]
(`neg_value`) when an input is beyond ±1e20, the policy is normalised by its own sum (at large
|V| the logsumexp's few units above the max vanish in V's rounding, so exp(V' − lse) alone need
not sum to 1), and moves off the grid get exactly 0. Inside the kernels a move off the grid
reads −inf from a padding around the grid, which exp turns into exactly 0 whatever the values;
standing still is always on the grid, so every max and every logsumexp stays finite.

Two kernels compute the same recursions. CPU tensors that need no gradient (the planner's case)
go to numpy kernels, which see all actions of a step at once through one strided view of a
padded copy of the grid and allocate every buffer once per call: a step is a dozen numpy calls,
whatever the number of actions. Everything else goes to torch kernels that build each step out
of place, so that autograd can run through them (∂V_0/∂r_t = D_t). Both are checked against an
enumeration of every path in tests/riskmap/planner/test_st_vi.py.
"""

from __future__ import annotations

import contextlib
import functools
import operator

import numpy as np
import torch
import torch.nn.functional as F
from numpy.lib.stride_tricks import as_strided

from rasterize.errors import InputError
from riskmap.planner.vi import neg_value, use_numpy_kernel

# Values whose sums cannot come near ±neg within any sane horizon need no clamping (see vi.py).
_CLAMP_ABOVE = 1e20


def spacetime_actions(max_forward: int, max_across: int = 1) -> np.ndarray:
    """[A, 2] int64 (d_row, d_col): d_row = 0, −1, …, −max_forward, each with d_col from
    −max_across to +max_across. A = (max_forward + 1) (2 max_across + 1); standing still is the
    action at index max_across."""
    moves = _moves(_non_negative_int(max_forward, "max_forward"),
                   _non_negative_int(max_across, "max_across"))
    return np.array(moves, dtype=np.int64)


@functools.lru_cache(maxsize=64)
def _moves(max_forward: int, max_across: int) -> tuple[tuple[int, int], ...]:
    return tuple((-forward, across) for forward in range(max_forward + 1)
                 for across in range(-max_across, max_across + 1))


def _non_negative_int(number, name: str) -> int:
    try:
        value = operator.index(number)
    except TypeError:
        raise InputError(f"{name} must be an integer >= 0, got {number!r}") from None
    if isinstance(number, bool) or value < 0:
        raise InputError(f"{name} must be an integer >= 0, got {number!r}")
    return value


def _check_maps(reward: torch.Tensor, goal: torch.Tensor) -> None:
    if reward.ndim != 4 or min(reward.shape) < 1 or \
            tuple(goal.shape) != (reward.shape[0], *reward.shape[2:]):
        raise ValueError(f"reward must be [B, T, H, W] (T >= 1) and goal [B, H, W] with the same "
                         f"B, H, W; got {tuple(reward.shape)} and {tuple(goal.shape)}")


def _not_finite() -> ValueError:
    return ValueError("reward and goal maps must be finite (no NaN or inf)")


def spacetime_value_iteration(reward: torch.Tensor, goal: torch.Tensor, max_forward: int,
                              max_across: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """(value [B, T, H, W] = V_1 … V_T, policy [B, T, A, H, W] = π_0 … π_{T−1})."""
    moves = _moves(_non_negative_int(max_forward, "max_forward"),
                   _non_negative_int(max_across, "max_across"))
    _check_maps(reward, goal)
    if use_numpy_kernel(reward) and use_numpy_kernel(goal):
        reward_np, goal_np = reward.numpy(), goal.numpy()
        if not (np.isfinite(reward_np).all() and np.isfinite(goal_np).all()):
            raise _not_finite()
        value, policy = _value_iteration_numpy(reward_np, goal_np.astype(reward_np.dtype, copy=False),
                                               max_forward, max_across)
        return torch.from_numpy(value), torch.from_numpy(policy)
    if not (torch.isfinite(reward).all() and torch.isfinite(goal).all()):
        raise _not_finite()
    return _value_iteration_torch(reward, goal.to(reward.dtype), moves)


def _value_iteration_numpy(reward: np.ndarray, goal: np.ndarray, max_forward: int, max_across: int
                           ) -> tuple[np.ndarray, np.ndarray]:
    """The CPU kernel. V_{t+1} is copied into the middle of a −inf padded grid, and `_options`
    views that grid as every action's V_{t+1}(next(s, a)) at once, [B, A, H, W]. Step t writes
    those options minus their max m_t(s) straight into π_t's slot of the policy, takes exp in
    place, sums over actions and divides: that is π_t, and the same sum gives
    V_t = r_t + m_t + log(sum)."""
    dtype = reward.dtype
    neg = neg_value(torch.float32 if dtype == np.float32 else torch.float64)
    b, horizon, h, w = reward.shape
    clamp = not (np.abs(reward).max() <= _CLAMP_ABOVE and np.abs(goal).max() <= _CLAMP_ABOVE)
    value = np.empty_like(reward)
    # The policy as [B, T, forward, across, H, W]: the action axis split the way `_options` is.
    policy = np.empty((b, horizon, max_forward + 1, 2 * max_across + 1, h, w), dtype)
    padded = np.full((b, h + max_forward, w + 2 * max_across), -np.inf, dtype)
    inside = padded[:, max_forward:, max_across:max_across + w]
    options = _options(padded, max_forward, max_across, h, w)
    across, top, total = np.empty((b, h + max_forward, w), dtype), np.empty((b, h, w), dtype), \
        np.empty((b, h, w), dtype)
    # Sums of inputs near the float limit overflow to inf on their way into the clamp.
    with np.errstate(over="ignore") if clamp else contextlib.nullcontext():
        np.add(reward[:, -1], goal, out=value[:, -1])
        if clamp:
            np.clip(value[:, -1], neg, -neg, out=value[:, -1])
        for t in range(horizon - 1, -1, -1):          # π_t and V_t from V_{t+1} = value[:, t]
            np.copyto(inside, value[:, t])
            _max_over_moves(padded, max_forward, max_across, across, top)
            step = policy[:, t]
            np.subtract(options, top[:, None, None], out=step)
            np.exp(step, out=step)                     # off the grid: exp(−inf) = 0
            np.sum(step, axis=(1, 2), out=total)       # >= 1: the largest option is exp(0)
            if t > 0:
                current = value[:, t - 1]
                np.log(total, out=current)
                current += top
                current += reward[:, t - 1]
                if clamp:
                    np.clip(current, neg, -neg, out=current)
            np.divide(step, total[:, None, None], out=step)
    return value, policy.reshape(b, horizon, -1, h, w)


def _options(padded: np.ndarray, max_forward: int, max_across: int, h: int, w: int) -> np.ndarray:
    """A read-only view [B, forward + 1, 2 across + 1, H, W] of `padded` [B, H + forward, W + 2
    across] (the grid at rows forward…, columns across…): element (b, i, j, row, col) is the
    padded cell of next((row, col), (−i, j − across)), i.e. padded[b, forward + row − i, col + j].
    Flattening (i, j) gives the order of `spacetime_actions`."""
    s_batch, s_row, s_col = padded.strides
    return as_strided(padded[:, max_forward:, :], shape=(padded.shape[0], max_forward + 1,
                                                         2 * max_across + 1, h, w),
                      strides=(s_batch, -s_row, s_col, s_row, s_col), writeable=False)


def _max_over_moves(padded: np.ndarray, max_forward: int, max_across: int, across: np.ndarray,
                    out: np.ndarray) -> None:
    """out(s) [B, H, W] = max over the actions of V(next(s, a)), from the −inf padded grid. The
    moves form a rectangle of rows and columns, so this is a running max across (into `across`,
    [B, H + forward, W]) and then forward: 2·max_across + max_forward calls, not one per action."""
    h, w = out.shape[1:]
    np.copyto(across, padded[:, :, :w])
    for j in range(1, 2 * max_across + 1):
        np.maximum(across, padded[:, :, j:j + w], out=across)
    np.copyto(out, across[:, max_forward:])
    for i in range(1, max_forward + 1):
        np.maximum(out, across[:, max_forward - i:max_forward - i + h], out=out)


def _value_iteration_torch(reward: torch.Tensor, goal: torch.Tensor, moves
                           ) -> tuple[torch.Tensor, torch.Tensor]:
    """The device (and autograd) kernel: each step gathers the options out of place, so that
    nothing a backward pass needs is overwritten."""
    neg = neg_value(reward.dtype)
    horizon = reward.shape[1]
    following = (reward[:, -1] + goal).clamp(neg, -neg)
    values, policies = [following], []
    for t in range(horizon - 1, -1, -1):
        options = _gather_moves(following, moves)
        policies.append(torch.softmax(options, dim=1))
        if t > 0:
            following = (reward[:, t - 1] + torch.logsumexp(options, dim=1)).clamp(neg, -neg)
            values.append(following)
    return torch.stack(values[::-1], dim=1), torch.stack(policies[::-1], dim=1)


def _gather_moves(value: torch.Tensor, moves) -> torch.Tensor:
    """[B, A, H, W]: value(next(s, a)) for every action, −inf where the move leaves the grid."""
    _, h, w = value.shape
    forward, across = -moves[-1][0], moves[-1][1]
    # Padded row forward + row + d_row and column across + col + d_col hold value(next(s, a)).
    padded = F.pad(value, (across, across, forward, 0), value=float("-inf"))
    return torch.stack([padded[:, forward + d_row:forward + d_row + h, across + d_col:across + d_col + w]
                        for d_row, d_col in moves], dim=1)


def spacetime_log_partition(value: torch.Tensor, start_cells, max_forward: int, max_across: int = 1
                            ) -> torch.Tensor:
    """[B]: V_0(s₀) = logsumexp over the moves on the grid of V_1(next(s₀, a))."""
    moves = _moves(_non_negative_int(max_forward, "max_forward"),
                   _non_negative_int(max_across, "max_across"))
    if value.ndim != 4 or min(value.shape) < 1:
        raise ValueError(f"value must be [B, T, H, W], got {tuple(value.shape)}")
    b, _, h, w = value.shape
    start = _start_cells(start_cells, b, h, w)
    neg = neg_value(value.dtype)
    if use_numpy_kernel(value):
        first = value[:, 0].numpy()
        log_z = np.empty(b, first.dtype)
        for i, (row, col) in enumerate(start.tolist()):
            # The cells one move away form a rectangle: up to max_forward rows ahead, max_across aside.
            ahead = first[i, max(row - max_forward, 0):row + 1, max(col - max_across, 0):col + max_across + 1]
            top = ahead.max()
            log_z[i] = top + np.log(np.exp(ahead - top).sum())
        return torch.from_numpy(np.clip(log_z, neg, -neg))
    padded = F.pad(value[:, 0], (max_across, max_across, max_forward, 0), value=float("-inf"))
    start, offsets = torch.from_numpy(start).to(value.device), torch.tensor(moves, device=value.device)
    rows = start[:, :1] + max_forward + offsets[:, 0]                    # [B, A]
    cols = start[:, 1:] + max_across + offsets[:, 1]
    options = padded[torch.arange(b, device=value.device)[:, None], rows, cols]
    return torch.logsumexp(options, dim=1).clamp(neg, -neg)


def _start_cells(start_cells, b: int, h: int, w: int) -> np.ndarray:
    """[B, 2] int64 on the CPU, checked to lie on the grid."""
    start = torch.as_tensor(start_cells).detach().cpu().long().numpy()
    if start.shape != (b, 2):
        raise ValueError(f"start_cells must be [B, 2] (row, col) with B = {b}, got {start.shape}")
    if ((start < 0) | (start >= (h, w))).any():
        raise ValueError(f"start cells {start.tolist()} lie outside the {h}x{w} grid")
    return start


def spacetime_visitation(policy: torch.Tensor, start_cells, max_forward: int, max_across: int = 1
                         ) -> torch.Tensor:
    """D [B, T, H, W] = D_1 … D_T, the probability of each cell at each step, from one-hot D_0."""
    moves = _moves(_non_negative_int(max_forward, "max_forward"),
                   _non_negative_int(max_across, "max_across"))
    if policy.ndim != 5 or policy.shape[2] != len(moves) or min(policy.shape) < 1:
        raise ValueError(f"policy must be [B, T, {len(moves)}, H, W] for max_forward="
                         f"{max_forward}, max_across={max_across}; got {tuple(policy.shape)}")
    b, _, _, h, w = policy.shape
    start = _start_cells(start_cells, b, h, w)
    if use_numpy_kernel(policy):
        return torch.from_numpy(_visitation_numpy(policy.numpy(), start, max_forward, max_across))
    return _visitation_torch(policy, torch.from_numpy(start).to(policy.device), moves)


def _visitation_numpy(policy: np.ndarray, start: np.ndarray, max_forward: int, max_across: int
                      ) -> np.ndarray:
    """The CPU kernel. Each step writes the flow π_t(a | s) D_t(s) of every action into a padded
    buffer and sums, for every cell, the flows of the actions that lead into it, read through one
    strided view (`_inflows`): two numpy calls a step. The padding is 0, so a cell's inflow from
    outside the grid is nothing; flow out of the grid is 0 because π_t is."""
    b, horizon, n_actions, h, w = policy.shape
    visits = np.empty((b, horizon, h, w), policy.dtype)
    mass = np.zeros((b, h, w), policy.dtype)
    mass[np.arange(b), start[:, 0], start[:, 1]] = 1.0
    flows = np.zeros((b, n_actions, h + max_forward, w + 2 * max_across), policy.dtype)
    inside = flows[:, :, :h, max_across:max_across + w]
    inflows = _inflows(flows, max_forward, max_across, h, w)
    for t in range(horizon):
        np.multiply(policy[:, t], mass[:, None], out=inside)
        np.sum(inflows, axis=(1, 2), out=visits[:, t])
        mass = visits[:, t]
    return visits


def _inflows(flows: np.ndarray, max_forward: int, max_across: int, h: int, w: int) -> np.ndarray:
    """A read-only view [B, forward + 1, 2 across + 1, H, W] of `flows` [B, A, H + forward, W + 2
    across] (each action's flow at rows 0…, columns across…): element (b, i, j, row, col) is the
    flow of action a = (−i, j − across) out of the cell it reaches (row, col) from, (row + i,
    col − j + across), which is flows[b, i (2 across + 1) + j, row + i, col + 2 across − j]."""
    s_batch, s_action, s_row, s_col = flows.strides
    return as_strided(flows[:, :, :, 2 * max_across:],
                      shape=(flows.shape[0], max_forward + 1, 2 * max_across + 1, h, w),
                      strides=(s_batch, (2 * max_across + 1) * s_action + s_row, s_action - s_col,
                               s_row, s_col), writeable=False)


def _visitation_torch(policy: torch.Tensor, start: torch.Tensor, moves) -> torch.Tensor:
    """The device (and autograd) kernel: each step scatters the flow of every action into a
    fresh buffer padded by one move on every side, so no shift needs clipping and nothing a
    backward pass needs is overwritten; flow that would leave the grid (0 anyway) falls into the
    padding."""
    b, horizon, _, h, w = policy.shape
    forward, across = -moves[-1][0], moves[-1][1]
    mass = policy.new_zeros((b, h, w))
    mass[torch.arange(b, device=policy.device), start[:, 0], start[:, 1]] = 1.0
    visits = []
    for t in range(horizon):
        flow = policy[:, t] * mass[:, None]
        padded = policy.new_zeros((b, h + forward, w + 2 * across))
        for a, (d_row, d_col) in enumerate(moves):
            padded[:, forward + d_row:forward + d_row + h, across + d_col:across + d_col + w] += flow[:, a]
        mass = padded[:, forward:, across:across + w]
        visits.append(mass)
    return torch.stack(visits, dim=1)
