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
    """[S, count, 2] waypoints (ego metres) evenly spaced along each path's cells, start excluded.

    paths [S, N + 1, 2] cells, moves [S] number of moves of each path.
    """
    frac = np.linspace(0.0, 1.0, count + 1)[1:]
    idx = np.round(moves[:, None] * frac[None, :]).astype(int)              # [S, count]
    cells = np.take_along_axis(paths, idx[..., None], axis=1)              # [S, count, 2]
    return ego_from_grid(cells, grid)


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
