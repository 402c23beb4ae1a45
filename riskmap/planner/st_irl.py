"""MaxEnt IRL in space-time (DESIGN §3b): the loss is built so that

    ∂loss/∂r_t = −(D_demo_t − D_t − v · D_t ⊙ N_t),     ∂loss/∂g = −(D_demo_T − D_T)

where D_demo_t is one-hot at the human's cell at step t, D_t the policy's visitation at step t and
N_t the other agents' footprints at their *recorded* positions at step t (a training signal only:
the network sees the present). Steps at which the human is off the grid carry no gradient: a
demonstration there says nothing about the grid's cells, and D_t's mass would otherwise be pushed
down wherever it went. The goal map g is learned too (`riskmap.planner.st_model`): the
log-likelihood of a demonstration is Σ_t r_t(s_t) + g(s_T) − V_0, whose gradient in g is
one-hot(s_T) − D_T. Shapes: rewards, visitation, N [B, T, G, G]; goal [B, G, G]; demo cells
[B, T, 2].
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from riskmap.planner.st_model import SpaceTimeConfig
from riskmap.planner.st_vi import spacetime_value_iteration, spacetime_visitation


@dataclass(frozen=True)
class SpaceTimeIRLConfig:
    spacetime: SpaceTimeConfig
    uncertainty_weight: float = 1.0   # v
    goal_variance: float = 5.0        # cells², of the goal map g


@dataclass
class SpaceTimeIRLStep:
    loss: torch.Tensor                # scalar; backward() injects ∂loss/∂r_t, ∂loss/∂g (batch mean)
    policy: torch.Tensor              # [B, T, A, G, G]
    visitation: torch.Tensor          # [B, T, G, G] D_t
    reward_gradient: torch.Tensor     # [B, T, G, G]


def demo_one_hot(cells: torch.Tensor, rows: int, cols: int, dtype=torch.float32) -> torch.Tensor:
    """[B, T, rows, cols] one-hot at each step's cell [B, T, 2]; all zero where the cell is −1."""
    b, steps, _ = cells.shape
    out = torch.zeros((b, steps, rows * cols), dtype=dtype, device=cells.device)
    on = cells[..., 0] >= 0
    flat = (cells[..., 0] * cols + cells[..., 1]).clamp(min=0)
    out.scatter_(2, flat[..., None], on[..., None].to(dtype))
    return out.view(b, steps, rows, cols)


def st_irl_step(reward: torch.Tensor, goal: torch.Tensor, batch: dict,
                config: SpaceTimeIRLConfig) -> SpaceTimeIRLStep:
    b, steps, rows, cols = reward.shape
    st = config.spacetime
    with torch.no_grad():
        _, policy = spacetime_value_iteration(reward.detach(), goal.detach(),
                                              st.max_forward, st.max_across)
        visits = spacetime_visitation(policy, batch["start_cell"], st.max_forward, st.max_across)
        demo = demo_one_hot(batch["st_demo"], rows, cols, reward.dtype)
        seen = (batch["st_demo"][..., 0] >= 0).to(reward.dtype)[..., None, None]   # [B, T, 1, 1]
        unc = batch["st_uncertainty"].to(reward.dtype)
        grad = -(demo - visits - config.uncertainty_weight * visits * unc) * seen
        goal_grad = -(demo[:, -1] - visits[:, -1]) * seen[:, -1]
    loss = ((grad * reward).sum() + (goal_grad * goal).sum()) / b
    return SpaceTimeIRLStep(loss, policy, visits, grad / b)


def demo_step_nll(visitation: torch.Tensor, demo_cells: torch.Tensor) -> torch.Tensor:
    """[B] mean over the steps the human is on the grid of −log D_t(human's cell): how surprised
    the policy is by where the human was at each time (e⁻²⁰ floor for cells it never reaches)."""
    b, steps, rows, cols = visitation.shape
    on = demo_cells[..., 0] >= 0
    flat = (demo_cells[..., 0] * cols + demo_cells[..., 1]).clamp(min=0)
    p = torch.gather(visitation.reshape(b, steps, -1), 2, flat[..., None]).squeeze(-1)
    nll = -torch.log(p.clamp_min(2e-9)) * on
    return nll.sum(1) / on.sum(1).clamp_min(1)
