"""Soft value iteration and state visitation on the risk-map grid (DESIGN §3).

Shapes: reward, goal, value [B, H, W]; policy [B, 5, H, W] over ACTIONS; start_cells [B, 2]
(row, col). Row 0 is the front of the grid, so "up" (row - 1) is forward.

    V⁰ = −∞;  Qⁿ(s, move a) = r(s) + γ Vⁿ⁻¹(next(s, a));  Qⁿ(s, end) = r(s) + γ g(s)
    Vⁿ(s) = logsumexp_a Qⁿ(s, a);  π(a | s) = exp(Q^N(s, a) − V^N(s))

Moves off the grid do not exist. −∞ is represented by a large finite negative (`neg_value`) so
that no arithmetic ever makes NaN; values are clamped into [neg, −neg] so that sums of huge
rewards cannot overflow to ±inf either. The policy is a softmax normalised by its own sum, not
exp(Q − V): at large |V| the few units of logsumexp above the max vanish in V's rounding, and the
rows would sum to up to 5. Off-grid moves get exactly 0 even where clamping ties the real
options with the stand-in (inputs at ±1e30 and beyond).

Two kernels compute the same recursions. On the CPU (the planner's case) a numpy kernel uses that
every Q of a cell shares its reward, V(s) = r(s) + logsumexp(γ V(neighbours), γ g(s)), with
every buffer allocated once: numpy's per-call overhead on 2 500-cell arrays is a fraction of
torch's, and these loops are a dozen small operations per step. On other devices the torch kernel runs. Both are checked
against the same float64 references (tests/riskmap/planner/test_vi.py).
"""

from __future__ import annotations

import numpy as np
import torch

ACTIONS = ("up", "down", "left", "right", "end")
UP, DOWN, LEFT, RIGHT, END = range(5)
# (d_row, d_col) of each move
MOVES = {UP: (-1, 0), DOWN: (1, 0), LEFT: (0, -1), RIGHT: (0, 1)}


def neg_value(dtype: torch.dtype) -> float:
    """The finite stand-in for −∞: far below any real value, far above overflow."""
    return -1e30 if dtype in (torch.float32, torch.float64) else -1e4


def _check(reward: torch.Tensor, goal: torch.Tensor, horizon: int) -> None:
    if reward.ndim != 3 or goal.shape != reward.shape:
        raise ValueError(f"reward and goal must both be [B, H, W]; got {tuple(reward.shape)} and "
                         f"{tuple(goal.shape)}")
    if horizon < 1:
        raise ValueError(f"horizon must be >= 1, got {horizon}")
    if not (torch.isfinite(reward).all() and torch.isfinite(goal).all()):
        raise ValueError("reward and goal maps must be finite (no NaN or inf)")


def soft_value_iteration(reward: torch.Tensor, goal: torch.Tensor, horizon: int,
                         gamma: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
    """(value [B, H, W], policy [B, 5, H, W]) after `horizon` soft Bellman backups."""
    _check(reward, goal, horizon)
    if use_numpy_kernel(reward):
        value, policy = _value_iteration_numpy(reward.numpy(), goal.numpy(), horizon, gamma)
        return torch.from_numpy(value), torch.from_numpy(policy)
    return _value_iteration_torch(reward, goal, horizon, gamma)


def use_numpy_kernel(tensor: torch.Tensor) -> bool:
    """The numpy kernels serve CPU tensors that need no gradient (VI and SVF never do)."""
    return tensor.device.type == "cpu" and not tensor.requires_grad and \
        tensor.dtype in (torch.float32, torch.float64)


def _value_iteration_numpy(reward: np.ndarray, goal: np.ndarray, horizon: int, gamma: float
                           ) -> tuple[np.ndarray, np.ndarray]:
    """The CPU kernel. The five options of every cell, γ V(neighbour) per move and γ g for `end`,
    live in one buffer [B, 5, H, W] whose move slots are refreshed from V each backup (a move off
    the grid keeps −∞); a backup is then max, subtract, exp, sum, log over that buffer: twelve
    numpy calls. Values are clamped only when an input is beyond ±1e20: below that, V stays
    within 2 · 1e20 + horizon · (1e20 + ln 5) of zero, far inside [neg, −neg]."""
    neg = neg_value(torch.float32 if reward.dtype == np.float32 else torch.float64)
    dtype = reward.dtype
    b, h, w = reward.shape
    clamp = not (np.abs(reward).max() <= 1e20 and np.abs(goal).max() <= 1e20)
    options = np.full((b, len(ACTIONS), h, w), neg, dtype=dtype)
    options[:, END] = np.clip(gamma * goal.astype(dtype, copy=False), neg, -neg)
    value = np.full((b, h, w), neg, dtype=dtype)
    # (slot of a move's option, the values of the cells it leads to) for moves inside the grid
    slots = ((options[:, UP, 1:, :], value[:, :-1, :]), (options[:, DOWN, :-1, :], value[:, 1:, :]),
             (options[:, LEFT, :, 1:], value[:, :, :-1]), (options[:, RIGHT, :, :-1], value[:, :, 1:]))
    top, total = np.empty_like(value), np.empty_like(value)
    work = np.empty_like(options)
    for _ in range(horizon):
        for slot, target in slots:
            if gamma == 1.0:
                np.copyto(slot, target)
            else:
                np.multiply(target, gamma, out=slot)
        np.max(options, axis=1, out=top)
        np.subtract(options, top[:, None], out=work)
        np.exp(work, out=work)
        np.sum(work, axis=1, out=total)
        np.log(total, out=total)
        total += top                                   # logsumexp of the options
        np.add(total, reward, out=value)
        if clamp:
            np.clip(value, neg, -neg, out=value)
    # π(a | s) ∝ exp(option_a − max), the last backup's, still in `work` (the shared reward
    # cancels), with the moves off the grid struck out.
    _strike_off_grid(work)
    return value, np.divide(work, work.sum(axis=1, keepdims=True), out=work)


def _strike_off_grid(policy) -> None:
    """Zero the moves [B, 5, H, W] that would leave the grid, in place."""
    policy[:, UP, 0, :] = 0.0
    policy[:, DOWN, -1, :] = 0.0
    policy[:, LEFT, :, 0] = 0.0
    policy[:, RIGHT, :, -1] = 0.0


def _value_iteration_torch(reward: torch.Tensor, goal: torch.Tensor, horizon: int,
                           gamma: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
    """The device kernel. One Q buffer [B, 5, H, W] is filled once with what never changes (the `end` column and the
    moves that leave the grid) and then only its in-grid move entries are rewritten each backup,
    in place, without per-step allocations.
    """
    neg = neg_value(reward.dtype)
    _, h, w = reward.shape
    q = (reward + gamma * neg).clamp(neg, -neg).unsqueeze(1).repeat(1, 5, 1, 1)
    q[:, END] = (reward + gamma * goal).clamp(neg, -neg)
    # (Q view, reward view, source slice of V) of each move whose target is inside the grid.
    targets = (
        (q[:, UP, 1:, :], reward[:, 1:, :], (slice(None), slice(None, -1), slice(None))),
        (q[:, DOWN, :-1, :], reward[:, :-1, :], (slice(None), slice(1, None), slice(None))),
        (q[:, LEFT, :, 1:], reward[:, :, 1:], (slice(None), slice(None), slice(None, -1))),
        (q[:, RIGHT, :, :-1], reward[:, :, :-1], (slice(None), slice(None), slice(1, None))),
    )
    value = reward.new_full(reward.shape, neg)
    moves = q[:, :END]
    for _ in range(horizon):
        for q_view, r_view, source in targets:
            if gamma == 1.0:
                torch.add(r_view, value[source], out=q_view)
            else:
                torch.add(r_view, value[source], alpha=gamma, out=q_view)
        moves.clamp_(neg, -neg)
        value = torch.logsumexp(q, dim=1)
    on_grid = torch.ones((1, len(ACTIONS), h, w), dtype=torch.bool, device=q.device)
    _strike_off_grid(on_grid)
    return value, torch.softmax(q.masked_fill(~on_grid, float("-inf")), dim=1)


def state_visitation(policy: torch.Tensor, start_cells: torch.Tensor, horizon: int
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """Expected visits (svf_path [B, H, W]) and end probabilities (svf_goal [B, H, W]).

    Mass starts one-hot at `start_cells`; each of `horizon` steps counts the mass on the path
    layer as a visit, sends the `end` share to the goal layer and moves the rest by the policy.
    Mass still on the path layer afterwards is 1 − svf_goal.sum().
    """
    b, a, h, w = policy.shape
    if a != len(ACTIONS):
        raise ValueError(f"policy must be [B, 5, H, W], got {tuple(policy.shape)}")
    start_cells = torch.as_tensor(start_cells, device=policy.device).long().reshape(b, 2)
    if ((start_cells < 0) | (start_cells >= torch.tensor([h, w], device=policy.device))).any():
        raise ValueError(f"start cells {start_cells.tolist()} lie outside the {h}x{w} grid")
    if use_numpy_kernel(policy):
        path, goal = _state_visitation_numpy(policy.numpy(), start_cells.numpy(), horizon)
        return torch.from_numpy(path), torch.from_numpy(goal)
    mass = policy.new_zeros((b, h, w))
    mass[torch.arange(b), start_cells[:, 0], start_cells[:, 1]] = 1.0
    svf_path = torch.zeros_like(mass)
    svf_goal = torch.zeros_like(mass)
    flow = policy.new_empty((b, END, h, w))
    moving = policy[:, :END]
    nxt = torch.empty_like(mass)
    for _ in range(horizon):
        svf_path += mass
        svf_goal += mass * policy[:, END]
        torch.mul(moving, mass.unsqueeze(1), out=flow)
        nxt.zero_()
        nxt[:, :-1, :] += flow[:, UP, 1:, :]
        nxt[:, 1:, :] += flow[:, DOWN, :-1, :]
        nxt[:, :, :-1] += flow[:, LEFT, :, 1:]
        nxt[:, :, 1:] += flow[:, RIGHT, :, :-1]
        mass, nxt = nxt, mass
    return svf_path, svf_goal


def _state_visitation_numpy(policy: np.ndarray, start_cells: np.ndarray, horizon: int
                            ) -> tuple[np.ndarray, np.ndarray]:
    """The CPU kernel of `state_visitation`: the same steps in numpy, buffers allocated once. The
    `end` share of a cell is the same at every step, so the goal layer is that share times the
    cell's visits, taken once at the end."""
    b, _, h, w = policy.shape
    mass = np.zeros((b, h, w), policy.dtype)
    mass[np.arange(b), start_cells[:, 0], start_cells[:, 1]] = 1.0
    svf_path = np.zeros_like(mass)
    flow = np.empty((b, END, h, w), policy.dtype)
    moving = policy[:, :END]
    nxt = np.empty_like(mass)
    for _ in range(horizon):
        svf_path += mass
        np.multiply(moving, mass[:, None], out=flow)
        nxt.fill(0.0)
        nxt[:, :-1, :] += flow[:, UP, 1:, :]
        nxt[:, 1:, :] += flow[:, DOWN, :-1, :]
        nxt[:, :, :-1] += flow[:, LEFT, :, 1:]
        nxt[:, :, 1:] += flow[:, RIGHT, :, :-1]
        mass, nxt = nxt, mass
    return svf_path, svf_path * policy[:, END]
