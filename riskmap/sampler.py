"""Trajectory sampler (planner paper §IV-C): paths sampled from the policy, clustered, the largest
cluster's most central path turned into 12 ego-frame waypoints over 6 s.

Shapes: policy [5, H, W] of one scene; paths [S, N + 1, 2] cells (row, col) with lengths [S]
(number of moves); waypoints [12, 2] ego-frame metres (x forward, y left).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from rasterize.config import GridConfig
from rasterize.frames import ego_from_grid
from riskmap.vi import END, MOVES


@dataclass(frozen=True)
class SamplerConfig:
    samples: int = 1000
    clusters: int = 10
    waypoints: int = 12


def sample_paths(policy: torch.Tensor, start: tuple[int, int], horizon: int, samples: int,
                 generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """All `samples` paths in one vectorised pass: (cells [S, horizon + 1, 2], moves [S])."""
    _, h, w = policy.shape
    moves = torch.tensor([MOVES[a] for a in range(END)], dtype=torch.long)
    cells = torch.tensor(start, dtype=torch.long).repeat(samples, 1)
    path = cells.new_empty((samples, horizon + 1, 2))
    path[:, 0] = cells
    alive = torch.ones(samples, dtype=torch.bool)
    length = torch.zeros(samples, dtype=torch.long)
    # Inverse-CDF sampling with all uniforms drawn at once: one comparison per step instead of a
    # multinomial call (the policy rows sum to 1; the last bin takes any rounding remainder).
    cdf = policy.permute(1, 2, 0).reshape(h * w, 5).double().cumsum(dim=1)
    cdf[:, -1] = 1.0
    uniforms = torch.rand((horizon, samples, 1), generator=generator, dtype=torch.float64)
    for t in range(horizon):
        action = (uniforms[t] >= cdf[cells[:, 0] * w + cells[:, 1]]).sum(dim=1).clamp(max=END)
        alive &= action != END
        step = moves[action.clamp(max=END - 1)] * alive.unsqueeze(1)
        cells = cells + step
        length += alive.long()
        path[:, t + 1] = cells
        if not alive.any():
            path[:, t + 2:] = cells.unsqueeze(1)
            break
    return path, length


def downsample(paths: np.ndarray, moves: np.ndarray, count: int, grid: GridConfig) -> np.ndarray:
    """[S, count, 2] waypoints (ego metres) evenly spaced in distance along each path, start
    excluded. paths [S, N + 1, 2] cells; moves [S] number of moves of each path.

    Spacing is by metres along the cell centres, not by cell count: highway cells are 4.8 m long
    and 0.8 m wide, and counting cells would make a lane change look like braking.
    """
    centres = ego_from_grid(paths, grid)                                    # [S, N + 1, 2]
    step = np.linalg.norm(np.diff(centres, axis=1), axis=2)                 # [S, N]
    step[np.arange(step.shape[1])[None, :] >= moves[:, None]] = 0.0        # beyond the end
    cum = np.concatenate([np.zeros((len(step), 1)), np.cumsum(step, axis=1)], axis=1)
    targets = cum[:, -1:] * np.linspace(0.0, 1.0, count + 1)[None, 1:]     # [S, count]
    # Index of the first cumulative length >= target, and the fraction within that move.
    hi = np.minimum((cum[:, None, :] < targets[:, :, None] - 1e-9).sum(axis=2), cum.shape[1] - 1)
    lo = np.maximum(hi - 1, 0)
    c_lo, c_hi = np.take_along_axis(cum, lo, 1), np.take_along_axis(cum, hi, 1)
    frac = np.where(c_hi > c_lo, (targets - c_lo) / np.maximum(c_hi - c_lo, 1e-12), 0.0)
    p_lo = np.take_along_axis(centres, lo[..., None], 1)
    p_hi = np.take_along_axis(centres, hi[..., None], 1)
    return p_lo + frac[..., None] * (p_hi - p_lo)


def sample_trajectory(policy: torch.Tensor, start: tuple[int, int], horizon: int, grid: GridConfig,
                      config: SamplerConfig = SamplerConfig(), seed: int = 0) -> np.ndarray:
    """Waypoints [config.waypoints, 2] in the ego frame: the most central path of the largest
    cluster of `config.samples` sampled paths. Deterministic given `seed`."""
    from sklearn.cluster import KMeans

    generator = torch.Generator().manual_seed(seed)
    paths, lengths = sample_paths(policy.detach().cpu(), start, horizon, config.samples, generator)
    paths, lengths = paths.numpy(), lengths.numpy()
    # Represent each path by its own evenly spaced waypoints, then cluster those.
    feats = downsample(paths, lengths, config.waypoints, grid)
    flat = feats.reshape(len(feats), -1)
    distinct = len(np.unique(flat, axis=0))
    k = max(1, min(config.clusters, distinct))
    labels = KMeans(n_clusters=k, n_init=1, random_state=seed).fit_predict(flat) if k > 1 \
        else np.zeros(len(flat), dtype=int)
    largest = np.bincount(labels).argmax()
    members = flat[labels == largest]
    centre = members.mean(axis=0)
    best = members[np.argmin(((members - centre) ** 2).sum(axis=1))]
    return best.reshape(config.waypoints, 2)
