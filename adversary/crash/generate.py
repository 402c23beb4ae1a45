"""Collision-scenario generation: optimise the non-ego latents of a logged scene (CRASH eq. 6-8).

Given the selection p [B, N] (row 0 the ego) and the adversary row adv = argmax p:

    L_adv = sum_i p_i sum_t |Y_i^t - Y_ego^t|^2  +  sum_t |Y_adv^t - Y_ego^t|^2        (eq. 6)
    L_reg = -mean_i (1 - p_i) log prior(z_i)  +  mean_i (1 - p_i) |z_i - z_i^init|^2   (eq. 7)
    L     = L_adv + L_reg + w_coll * non-adversary collisions + w_off * off-road        (eq. 8 +
                                                                                  STRIVE's terms)

positions in units of `position_scale_m`, means over the real non-ego agents. The collision
term covers every pair that does not involve the adversary (non-ego pairs and ego-other pairs),
each vehicle approximated by three discs along its length; the off-road term is the distance of
every non-ego box corner to the drivable area. Latents start at the posterior mean of the logged
scene and are optimised with Adam.

The ego is never decoded: its states are fixed to `ego_future` (the logged one for a replayed
ego). For a closed-loop ego, `replan(tracks) -> ego_future` re-runs the black-box planner on the
current trajectories every `replan_every` iterations (k; 1 is STRIVE's setting), and the ego's
row follows its output from then on.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from adversary.crash.batch import Batch, sample_field
from adversary.crash.traffic_model import Encoded, TrafficModel, log_normal


@dataclass(frozen=True)
class GenerationConfig:
    iterations: int = 300             # 300 for a replayed ego, 200 for a closed-loop one (CRASH)
    lr: float = 0.05                  # Adam on the latents
    replan_every: int = 20            # k: planner re-runs every k iterations (closed loop only)
    position_scale_m: float = 10.0    # L_adv is computed on positions / this
    collision_weight: float = 20.0    # STRIVE's weights for the non-ego penalties
    off_road_weight: float = 20.0
    stop_on_collision: bool = True    # stop once the decoded adversary overlaps the ego (checked
                                      # every `check_every` iterations; with a closed-loop ego only
                                      # if it still does after a fresh re-plan): the remaining
                                      # iterations cannot turn a collision into a better one on
                                      # the metrics that count, and they cost most of the time
    check_every: int = 10


@dataclass
class Generation:
    traj: torch.Tensor                # [B, N, F, 4] final trajectories, ego row = ego_future
    z: torch.Tensor                   # [B, N, latent]
    p: torch.Tensor                   # [B, N]
    adversary: torch.Tensor           # [B] row of the adversary (-1 without candidates)
    losses: list[dict]                # per iteration (every 10th kept), scalars of the first scene
    replans: int
    iterations: int                   # iterations run (fewer than configured after an early stop)
    seconds: float


def _discs(traj: torch.Tensor, sizes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Disc centres [B, N, F, 3, 2] and radii [B, N, 1, 1] covering each box."""
    offsets = torch.tensor([-1.0, 0.0, 1.0]) / 3.0
    length, width = sizes[..., 0], sizes[..., 1]
    heading = torch.stack([torch.cos(traj[..., 2]), torch.sin(traj[..., 2])], -1)       # [B, N, F, 2]
    shift = offsets.view(1, 1, 1, 3, 1) * length[:, :, None, None, None] * heading[..., None, :]
    radius = torch.sqrt((length / 6.0) ** 2 + (width / 2.0) ** 2)
    return traj[..., None, :2] + shift, radius[:, :, None, None]


def collision_penalty(traj: torch.Tensor, sizes: torch.Tensor, pair_mask: torch.Tensor) -> torch.Tensor:
    """[B] sum over masked pairs [B, N, N] and steps of the deepest disc overlap (m)."""
    centres, radius = _discs(traj, sizes)
    b, n = traj.shape[:2]
    a = centres[:, :, None, :, :, None, :]                          # [B, N, 1, F, 3, 1, 2]
    c = centres[:, None, :, :, None, :, :]                          # [B, 1, N, F, 1, 3, 2]
    dist = (a - c).norm(dim=-1)                                     # [B, N, N, F, 3, 3]
    reach = radius[:, :, None, :, :, None] + radius[:, None, :, :, :, None]
    overlap = torch.relu(reach.view(b, n, n, 1, 1, 1) - dist).amax(dim=(-1, -2))      # [B, N, N, F]
    return (overlap.sum(-1) * pair_mask.float()).sum((-1, -2)) / 2.0


def off_road_penalty(batch: Batch, traj: torch.Tensor, agents: torch.Tensor) -> torch.Tensor:
    """[B] mean over the masked agents [B, N] of the summed corner distances to the road (m)."""
    length, width = batch.sizes[..., 0, None, None], batch.sizes[..., 1, None, None]
    c, s = torch.cos(traj[..., 2])[..., None], torch.sin(traj[..., 2])[..., None]
    u = torch.tensor([0.5, 0.5, -0.5, -0.5]).view(1, 1, 1, 4) * length
    v = torch.tensor([0.5, -0.5, 0.5, -0.5]).view(1, 1, 1, 4) * width
    corners = torch.stack([traj[..., 0, None] + c * u - s * v, traj[..., 1, None] + s * u + c * v], -1)
    dist = sample_field(batch, corners)                             # [B, N, F, 4]
    per_agent = dist.sum((-1, -2))
    w = agents.float()
    return (per_agent * w).sum(-1) / w.sum(-1).clamp(min=1.0)


def attack_loss(model: TrafficModel, batch: Batch, enc: Encoded, z: torch.Tensor, z_init: torch.Tensor,
                p: torch.Tensor, adversary: torch.Tensor, ego_future: torch.Tensor,
                config: GenerationConfig) -> tuple[torch.Tensor, torch.Tensor, dict]:
    """(loss [B], trajectories [B, N, F, 4], parts of scene 0) of the module docstring."""
    b, n = p.shape
    fixed = torch.zeros(b, n, ego_future.shape[1], 4)
    fixed[:, 0] = ego_future
    fixed_mask = torch.zeros(b, n, dtype=torch.bool)
    fixed_mask[:, 0] = True
    traj = model.decode(batch, enc, z, fixed, fixed_mask)
    others = batch.agent_mask.clone()
    others[:, 0] = False
    sq = ((traj[..., :2] - ego_future[:, None, :, :2]) / config.position_scale_m).pow(2).sum(-1).sum(-1)  # [B, N]
    has_adv = adversary >= 0
    hard = torch.where(has_adv, sq.gather(1, adversary.clamp(min=0)[:, None]).squeeze(1), torch.zeros(b))
    l_adv = (p * sq).sum(-1) + hard
    keep = (1.0 - p) * others.float()
    count = others.float().sum(-1).clamp(min=1.0)
    log_prior = log_normal(z, enc.prior_mu, enc.prior_logvar)
    l_reg = (-(keep * log_prior).sum(-1) + (keep * (z - z_init).pow(2).sum(-1)).sum(-1)) / count
    is_adv = torch.zeros(b, n, dtype=torch.bool)
    is_adv[has_adv, adversary[has_adv]] = True
    live = batch.agent_mask & ~is_adv
    pair = live[:, :, None] & live[:, None, :] & ~torch.eye(n, dtype=torch.bool)[None]
    l_coll = collision_penalty(traj, batch.sizes, pair)
    l_off = off_road_penalty(batch, traj, others)
    loss = l_adv + l_reg + config.collision_weight * l_coll + config.off_road_weight * l_off
    parts = {"adv": float(l_adv[0].detach()), "reg": float(l_reg[0].detach()),
             "collision": float(l_coll[0].detach()), "off_road": float(l_off[0].detach())}
    return loss, traj, parts


def generate(model: TrafficModel, batch: Batch, p: torch.Tensor, ego_future: torch.Tensor,
             config: GenerationConfig = GenerationConfig(),
             replan: Callable[[torch.Tensor], torch.Tensor] | None = None,
             z_init: torch.Tensor | None = None) -> Generation:
    """Optimise the latents of every scene of `batch` (independently) against ego_future [B, F, 4].

    `replan(traj [B, N, F, 4]) -> ego_future [B, F, 4]` is called every `config.replan_every`
    iterations (after the first) when given. The model's weights are not touched.
    """
    started = time.perf_counter()
    with torch.no_grad():
        enc = model.encode(batch)
        if z_init is None:
            z_init, _ = model.posterior_of(batch, enc)
    adversary = torch.where(p.sum(-1) > 0, p.argmax(-1), torch.full((p.shape[0],), -1))
    z = z_init.clone().requires_grad_(True)
    optimiser = torch.optim.Adam([z], lr=config.lr)
    ego_future = ego_future.clone()
    losses, replans, iterations = [], 0, 0
    for it in range(config.iterations):
        if replan is not None and it > 0 and it % config.replan_every == 0:
            with torch.no_grad():
                current = _decode_with_ego(model, batch, enc, z, ego_future)
            ego_future = replan(current).detach()
            replans += 1
        if config.stop_on_collision and it > 0 and it % config.check_every == 0:
            with torch.no_grad():
                hit = adversary_overlaps(_decode_with_ego(model, batch, enc, z, ego_future), batch, adversary)
                if hit.all() and replan is not None and it % config.replan_every != 0:
                    ego_future = replan(_decode_with_ego(model, batch, enc, z, ego_future)).detach()
                    replans += 1
                    hit = adversary_overlaps(_decode_with_ego(model, batch, enc, z, ego_future), batch,
                                             adversary)
            if hit.all():
                break
        iterations = it + 1
        loss, _, parts = attack_loss(model, batch, enc, z, z_init, p, adversary, ego_future, config)
        optimiser.zero_grad()
        loss.sum().backward()
        # The ego's latent is never used (its states are fixed); keep it at its start.
        z.grad[:, 0] = 0.0
        optimiser.step()
        if it % 10 == 0 or it == config.iterations - 1:
            losses.append({"iteration": it, **parts})
    with torch.no_grad():
        traj = _decode_with_ego(model, batch, enc, z, ego_future)
    return Generation(traj, z.detach(), p, adversary, losses, replans, iterations,
                      time.perf_counter() - started)


def adversary_overlaps(traj: torch.Tensor, batch: Batch, adversary: torch.Tensor) -> torch.Tensor:
    """[B] bool: the adversary's discs overlap the ego's (row 0) at some step."""
    b, n = traj.shape[:2]
    pair = torch.zeros(b, n, n, dtype=torch.bool)
    has = adversary >= 0
    pair[has, 0, adversary[has]] = True
    pair[has, adversary[has], 0] = True
    return collision_penalty(traj, batch.sizes, pair) > 0.0


def _decode_with_ego(model, batch, enc, z, ego_future) -> torch.Tensor:
    b, n = z.shape[:2]
    fixed = torch.zeros(b, n, ego_future.shape[1], 4)
    fixed[:, 0] = ego_future
    mask = torch.zeros(b, n, dtype=torch.bool)
    mask[:, 0] = True
    return model.decode(batch, enc, z, fixed, mask)


def logged_ego_future(batch: Batch) -> torch.Tensor:
    """The ego's logged future [B, F, 4] (x, y, heading, speed) from batch.future."""
    f = batch.future[:, 0]
    return torch.stack([f[..., 0], f[..., 1], torch.atan2(f[..., 3], f[..., 2]), f[..., 4]], -1)


def to_numpy(x: torch.Tensor) -> np.ndarray:
    return x.detach().cpu().numpy()
