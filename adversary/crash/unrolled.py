"""The selector's objective through the generation loss: a few differentiable steps of the attack.

For a scene with candidates (mask M) and the selector's p = ASM(Z, M), the generator would start
at the posterior mean z_0 = z_init of the logged scene and descend L(z; p) (`attack_loss`, the
task-coupled loss of CRASH eq. 6-8 plus STRIVE's collision and off-road terms, against the logged
ego). We unroll K of its steps as plain gradient descent, keeping the graph,

    z_{k+1} = z_k - eta * dL(z_k; p)/dz          (create_graph: z_K is a function of p)

(each agent's step clipped to a norm of MAX_STEP: unclipped, on the shipped highway model, the
loss after 5 steps rose on 11 of 120 scenes at eta = 0.5 and on most at 1.0, on none at 0.25)

and train the selector to minimise L(z_K; p) after them. The gradient reaches p twice: directly
(p weights the distance terms and, through 1 - p, the regulariser) and through the unroll (p
decides how hard each latent is pulled towards the ego and held to its prior, so z_K moves with
p). The traffic model is frozen; the ego's latent is never moved (its states are the log).

The hard term |Y_adv - Y_ego|^2 with adv = argmax p has no gradient in p. In the unrolled steps it
is kept exactly as the generator has it (argmax), so the inner dynamics are the generator's. In
the final loss it is replaced by its straight-through surrogate: the forward value is still the
generator's hard term, the backward pass treats one-hot(argmax p) as p, i.e. it adds
sum_i (p_i - stopgrad p_i) |Y_i - Y_ego|^2 (value 0). Without it only the soft half of L_adv
would speak for the distances in p's gradient while the regulariser speaks in full, although the
distance of argmax p is what the generator goes on to optimise. The surrogate is not used inside
the unroll: there its zero value would still add a second-order term (d/dp of its z-gradient)
that the forward dynamics do not have.

The loss is the generator's own `attack_loss`, whose collision penalty uses smoothed distances so
that every unrolled step can differentiate it twice.
"""

from __future__ import annotations

import torch

from adversary.crash.batch import Batch
from adversary.crash.generate import (
    DISTANCE_EPS_M,
    GenerationConfig,
    adversarial_distance,
    adversary_of,
    attack_loss,
    logged_ego_future,
)
from adversary.crash.selection import candidates
from adversary.crash.traffic_model import Encoded, TrafficModel

MAX_STEP = 2.0      # latent units per agent and unrolled step; 5 steps then reach about as far as
                    # the generator's 60 Adam iterations of 0.05 per coordinate (latent size 32)


def straight_through_hard(traj: torch.Tensor, ego_future: torch.Tensor, p: torch.Tensor,
                          config: GenerationConfig) -> torch.Tensor:
    """[B] zero-valued term whose gradient in p is each agent's adversarial distance to the ego
    (the straight-through part of the hard term; module docstring)."""
    return ((p - p.detach()) * adversarial_distance(traj, ego_future, config)).sum(-1)


def unroll(model: TrafficModel, batch: Batch, enc: Encoded, z_init: torch.Tensor, p: torch.Tensor,
           ego_future: torch.Tensor, steps: int, eta: float, config: GenerationConfig) -> torch.Tensor:
    """z_K [B, N, latent] after `steps` differentiable gradient steps on L(z; p) from z_init."""
    adversary = adversary_of(p)
    movable = torch.ones_like(z_init)
    movable[:, 0] = 0.0                              # the ego's latent is never used
    z = z_init.detach().clone().requires_grad_(True)
    for _ in range(steps):
        loss, _, _ = attack_loss(model, batch, enc, z, z_init, p, adversary, ego_future, config)
        (grad,) = torch.autograd.grad(loss.sum(), z, create_graph=True)
        step = eta * grad * movable
        # A trust region: no agent's latent moves more than MAX_STEP per step (smooth norm, so
        # that the ego's and padding's zero gradients stay twice differentiable).
        norm = (step.pow(2).sum(-1, keepdim=True) + DISTANCE_EPS_M ** 2).sqrt()
        z = z - step * (MAX_STEP / norm).clamp(max=1.0)
    return z


def unrolled_loss(model: TrafficModel, batch: Batch, selector, mam: bool, steps: int, eta: float,
                  config: GenerationConfig | None = None, enc: Encoded | None = None,
                  z_init: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(final generation loss [B] after the unroll, p [B, N]) of the selector's choice; scenes
    without candidates get loss 0. Differentiable in the selector's parameters."""
    config = config or GenerationConfig()
    if enc is None or z_init is None:
        with torch.no_grad():
            enc = model.encode(batch)
            z_init, _ = model.posterior_of(batch, enc)
    mask = candidates(batch, mam)
    p = selector(enc.context, mask)
    ego = logged_ego_future(batch)
    z = unroll(model, batch, enc, z_init, p, ego, steps, eta, config)
    loss, traj, _ = attack_loss(model, batch, enc, z, z_init, p, adversary_of(p), ego, config)
    loss = loss + straight_through_hard(traj, ego, p, config)
    return torch.where(mask.any(-1), loss, torch.zeros_like(loss)), p
