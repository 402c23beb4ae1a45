"""Who becomes the adversary: CRASH's MAM and ASM, and the baselines they are compared with.

Every selector returns p [B, N] over the rows of a batch: row 0 (the ego) and padding get 0,
the candidates sum to 1, the adversary is argmax p.

    Motion-Aware Masking (MAM)   d_i = mean over the past steps of |q_i^t - q_i^(t-1)|;
                                 agent i is a candidate only if d_i > delta (1e-4 m)
    ASM                          cross attention, the ego's latent Z_ego as the query over the
                                 (masked) non-ego latents: a_i = softmax_i(q . k_i / sqrt(d)),
                                 alpha_i = a_i * v_i (per head); AdvHead(alpha_i, Z_i) -> logit,
                                 softmax over the candidates -> p
    distance (STRIVE)            softmin over (agent, future step) of the distance to the ego,
                                 w[i, t] = exp(-d[i, t] / tau) / sum exp(...); p_i = sum_t w[i, t];
                                 agents behind the ego now (x < 0 in the scene frame) excluded
    nearest                      the candidate nearest the ego now
    random                       a uniformly drawn candidate
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from adversary.crash.batch import Batch
from adversary.crash.traffic_model import _mlp

MAM_DELTA_M = 1e-4
SELECTORS = ("crash", "crash-no-mam", "distance", "distance+mam", "nearest", "random")


def candidates(batch: Batch, mam: bool, delta_m: float = MAM_DELTA_M) -> torch.Tensor:
    """[B, N] bool: the non-ego agents that may be chosen (those that move, with MAM)."""
    mask = batch.agent_mask.clone()
    mask[:, 0] = False
    if mam:
        steps = (batch.past[:, :, 1:, :2] - batch.past[:, :, :-1, :2]).norm(dim=-1)
        pair_valid = (batch.past_valid[:, :, 1:] & batch.past_valid[:, :, :-1]).float()
        motion = (steps * pair_valid).sum(-1) / pair_valid.sum(-1).clamp(min=1.0)
        mask &= motion > delta_m
    return mask


def _masked_softmax(logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    logits = logits.masked_fill(~mask, float("-inf"))
    p = torch.softmax(logits, dim=-1)
    return torch.nan_to_num(p * mask, nan=0.0)     # a scene without candidates gets all zeros


def distance_weights(traj: torch.Tensor, ego_future: torch.Tensor, batch: Batch, mask: torch.Tensor,
                     temperature_m: float = 2.0) -> torch.Tensor:
    """STRIVE's softmin selection from decoded futures traj [B, N, F, 4] and the ego's [B, F, 4]."""
    d = (traj[..., :2] - ego_future[:, None, :, :2]).norm(dim=-1)               # [B, N, F]
    eligible = mask & (batch.past[:, :, -1, 0] >= 0.0)                          # not behind the ego
    logits = (-d / temperature_m).masked_fill(~eligible[..., None], float("-inf"))
    b = logits.shape[0]
    w = torch.softmax(logits.reshape(b, -1), dim=-1).reshape(d.shape)
    return torch.nan_to_num(w, nan=0.0).sum(-1)


def nearest_weights(batch: Batch, mask: torch.Tensor) -> torch.Tensor:
    d = batch.past[:, :, -1, :2].norm(dim=-1).masked_fill(~mask, float("inf"))
    p = torch.zeros_like(d)
    has = mask.any(-1)
    p[has, d[has].argmin(-1)] = 1.0
    return p


def random_weights(mask: torch.Tensor, rng: np.random.Generator) -> torch.Tensor:
    p = torch.zeros(mask.shape)
    for b in range(mask.shape[0]):
        rows = np.flatnonzero(mask[b].numpy())
        if len(rows):
            p[b, int(rng.choice(rows))] = 1.0
    return p


class SelectionModule(nn.Module):
    """ASM: ego-query cross attention over the non-ego latents, then AdvHead (module docstring)."""

    def __init__(self, hidden: int, heads: int = 4):
        super().__init__()
        if hidden % heads:
            raise ValueError("hidden must be a multiple of heads")
        self.heads, self.head_dim = heads, hidden // heads
        self.query, self.key, self.value = (nn.Linear(hidden, hidden) for _ in range(3))
        self.adv_head = _mlp([2 * hidden, hidden, 1])

    def forward(self, context: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """context Z [B, N, D] (row 0 the ego), mask [B, N] candidates -> p [B, N]."""
        b, n, d = context.shape
        z_mam = context * mask[..., None].float()                               # eq. 3: M (.) Z
        q = self.query(context[:, 0]).view(b, self.heads, 1, self.head_dim)
        k = self.key(z_mam).view(b, n, self.heads, self.head_dim).transpose(1, 2)
        v = self.value(z_mam).view(b, n, self.heads, self.head_dim).transpose(1, 2)
        scores = (q @ k.transpose(-1, -2)) / math.sqrt(self.head_dim)           # [B, H, 1, N]
        attn = _masked_softmax(scores.squeeze(2), mask[:, None, :].expand(-1, self.heads, -1))
        alpha = (attn[..., None] * v).transpose(1, 2).reshape(b, n, d)          # eq. 4, per agent
        logits = self.adv_head(torch.cat([alpha, context], dim=-1)).squeeze(-1)  # eq. 5
        return _masked_softmax(logits, mask)
