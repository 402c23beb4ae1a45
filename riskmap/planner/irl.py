"""Maximum-entropy IRL with the uncertainty-overlap term (planner paper eq. 5, DESIGN §3).

Value iteration and state visitation run without gradient; the loss is built so that

    ∂loss/∂r = −(D_demo − D_policy − v · D_policy ⊙ N)

is injected into the risk map r: gradient descent raises reward on demonstrated cells, lowers it
where the policy visits too much, and lowers it where those visits overlap the agents'
uncertainty N. Shapes: maps [B, G, G]; start and goal cells [B, 2]; demo paths [B, L, 2].
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from riskmap.planner.vi import END, MOVES, soft_value_iteration, state_visitation


@dataclass(frozen=True)
class IRLConfig:
    horizon: int = 80                 # value-iteration steps (and state-visitation steps)
    gamma: float = 1.0
    uncertainty_weight: float = 1.0   # v
    goal_variance: float = 5.0        # cells², of the goal map
    # The risk-limited goal (riskmap.planner.risk_goal.RiskGoalConfig's fields), None: the route
    # rule's goal as given. With it each window's goal is held short where the model's own
    # (detached) risk map blocks the route, as the planner does in closed loop.
    risk_goal: dict | None = None


def goal_log_map(goal_cells: torch.Tensor, rows: int, cols: int, variance: float | torch.Tensor,
                 dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """log of the Gaussian goal map [B, rows, cols]: −d²/(2·variance), d in cells; `variance` one
    number or one per sample [B]. Exact far out, where the goal map itself underflows."""
    r = torch.arange(rows, dtype=dtype).view(1, rows, 1)
    c = torch.arange(cols, dtype=dtype).view(1, 1, cols)
    gr = goal_cells[:, 0].to(dtype).view(-1, 1, 1)
    gc = goal_cells[:, 1].to(dtype).view(-1, 1, 1)
    if isinstance(variance, torch.Tensor):
        variance = variance.to(dtype).view(-1, 1, 1)
    return -((r - gr) ** 2 + (c - gc) ** 2) / (2.0 * variance)


def goal_cells(risk: torch.Tensor, batch: dict, config: IRLConfig
               ) -> tuple[torch.Tensor, float | torch.Tensor]:
    """The goal value iteration is pulled to: ([B, 2] cells, variance in cells²): the batch's
    cells (the route rule's) and `config.goal_variance`, or with `config.risk_goal` those the risk
    map holds back, with their own variance, per sample (`riskmap.planner.risk_goal`)."""
    if config.risk_goal is None:
        return batch["goal_cell"], config.goal_variance
    from riskmap.planner.risk_goal import RiskGoalConfig, risk_goal_cells

    cells, variance = risk_goal_cells(risk.detach().cpu().numpy(), batch["route_cells"].cpu().numpy(),
                                      batch["motion"][:, 0, 0, 0].cpu().numpy(), batch["goal_cell"].cpu().numpy(),
                                      config.goal_variance, RiskGoalConfig(**config.risk_goal))
    device = batch["goal_cell"].device
    return torch.from_numpy(cells).to(device), torch.from_numpy(variance).to(device)


@dataclass
class IRLStep:
    """Everything one IRL step computes; `loss` carries the injected gradient."""

    loss: torch.Tensor            # scalar, backward() gives ∂/∂r as above (mean over the batch)
    policy: torch.Tensor          # [B, 5, G, G]
    svf: torch.Tensor             # [B, G, G] expected visits of the policy
    svf_goal: torch.Tensor        # [B, G, G]
    reward_gradient: torch.Tensor  # [B, G, G] ∂loss/∂r per sample


def irl_step(risk: torch.Tensor, batch: dict, config: IRLConfig) -> IRLStep:
    b, g_rows, g_cols = risk.shape
    cells, variance = goal_cells(risk, batch, config)
    goal = goal_log_map(cells, g_rows, g_cols, variance, risk.dtype)
    with torch.no_grad():
        _, policy = soft_value_iteration(risk.detach(), goal.to(risk.device), config.horizon,
                                         config.gamma)
        svf, svf_goal = state_visitation(policy, batch["start_cell"], config.horizon)
        demo = batch["demo"][:, 0].to(risk.dtype)
        unc = batch["uncertainty"].to(risk.dtype)
        grad = -(demo - svf - config.uncertainty_weight * svf * unc)
    loss = (grad * risk).sum() / b
    return IRLStep(loss, policy, svf, svf_goal, grad / b)


def demo_negative_log_likelihood(policy: torch.Tensor, demo_path: torch.Tensor) -> torch.Tensor:
    """[B] −log π of each demonstration's action sequence: its moves, then `end` at its last cell.

    demo_path [B, L, 2] cells padded with −1.
    """
    b, _, h, w = policy.shape
    valid = demo_path[..., 0] >= 0                                   # [B, L]
    cells = demo_path.clamp(min=0)
    delta = cells[:, 1:] - cells[:, :-1]                             # [B, L−1, 2]
    action = torch.full(delta.shape[:2], END, dtype=torch.long, device=policy.device)
    for a, (dr, dc) in MOVES.items():
        action[(delta[..., 0] == dr) & (delta[..., 1] == dc)] = a
    moving = valid[:, 1:]                                           # the step leads somewhere
    last = valid.sum(1) - 1                                         # index of the end cell
    flat = policy.reshape(b, 5, h * w)
    idx = cells[..., 0] * w + cells[..., 1]                          # [B, L]
    logp = torch.log(flat.clamp_min(1e-30))
    step_logp = torch.gather(logp, 2, idx[:, None, :-1].expand(b, 5, -1))   # [B, 5, L−1]
    move_logp = torch.gather(step_logp, 1, action[:, None, :]).squeeze(1) * moving
    end_idx = torch.gather(idx, 1, last[:, None]).squeeze(1)
    end_logp = logp[torch.arange(b), END, end_idx]
    return -(move_logp.sum(1) + end_logp)
