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
from riskmap.planner.vi import END, MOVES


@dataclass(frozen=True)
class SamplerConfig:
    samples: int = 1000
    clusters: int = 10
    waypoints: int = 12


def sample_paths(policy: torch.Tensor, start: tuple[int, int], horizon: int, samples: int,
                 generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """All `samples` paths in one vectorised pass: (cells [S, horizon + 1, 2], moves [S]).

    Inverse-CDF sampling with all uniforms drawn at once from `generator`: one comparison per
    step instead of a multinomial call (the policy rows sum to 1; the last bin takes any rounding
    remainder). The walk itself runs in numpy, whose per-call overhead on 1000-element arrays is
    a fraction of torch's.
    """
    _, h, w = policy.shape
    moves = np.array([MOVES[a] for a in range(END)] + [(0, 0)], dtype=np.int64)   # end: stay
    cdf = policy.detach().cpu().permute(1, 2, 0).reshape(h * w, 5).double().cumsum(dim=1).numpy()
    cdf[:, -1] = 1.0
    uniforms = torch.rand((horizon, samples, 1), generator=generator, dtype=torch.float64).numpy()
    path = np.empty((samples, horizon + 1, 2), dtype=np.int64)
    path[:, 0] = start
    cells = path[:, 0].copy()
    alive = np.ones(samples, dtype=bool)
    length = np.zeros(samples, dtype=np.int64)
    for t in range(horizon):
        action = np.minimum((uniforms[t] >= cdf[cells[:, 0] * w + cells[:, 1]]).sum(axis=1), END)
        alive &= action != END
        cells += moves[np.where(alive, action, END)]
        length += alive
        path[:, t + 1] = cells
        if not alive.any():
            path[:, t + 2:] = cells[:, None]
            break
    return torch.from_numpy(path), torch.from_numpy(length)


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
    # Index of the first cumulative length >= target, and the fraction within that move: one
    # searchsorted over all rows at once, each row lifted above the previous one by an offset.
    n = cum.shape[1]
    offset = (np.arange(len(cum)) * (cum[:, -1].max() + 1.0))[:, None]
    below = np.searchsorted((cum + offset).ravel(), (targets - 1e-9 + offset).ravel(), side="left")
    hi = np.minimum(below.reshape(targets.shape) - np.arange(len(cum))[:, None] * n, n - 1)
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
    # Columns after the longest path only repeat its end: drop them before measuring lengths.
    paths, lengths = paths[:, :int(lengths.max()) + 1].numpy(), lengths.numpy()
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
