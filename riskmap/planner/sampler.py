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
from rasterize.errors import InputError
from rasterize.frames import ego_from_grid, grid_from_ego
from riskmap.planner.vi import END, MOVES

TIMINGS = ("uniform", "kinematic")


@dataclass(frozen=True)
class SamplerConfig:
    """`timing`: how the chosen path is spread over the 6 s. `uniform`: waypoints evenly spaced
    in distance (constant speed from the start, whatever the ego's speed now); `kinematic`: the
    ego's current speed, changed at the one constant acceleration that ends the path at 6 s
    (at most `max_accel_mps2`; where that would mean reversing, braking to a stop at its end):
    `kinematic_arc_lengths`. Checkpoints from before `timing` existed plan `uniform`."""

    samples: int = 1000
    clusters: int = 10
    waypoints: int = 12
    timing: str = "kinematic"
    max_accel_mps2: float = 3.0
    dt_s: float = 0.5                 # seconds between waypoints
    keep_gap: bool = True             # re-time behind vehicles on the path (`gap_keeping`)
    gap_prediction: str = "straight"  # how gap keeping predicts the others: straight | lanes

    def __post_init__(self) -> None:
        if self.gap_prediction not in ("straight", "lanes"):
            raise InputError(f"sampler gap_prediction {self.gap_prediction!r} is unknown; use "
                             "straight or lanes")
        if self.timing not in TIMINGS:
            raise InputError(f"sampler timing {self.timing!r} is unknown; use one of {', '.join(TIMINGS)}")


def kinematic_arc_lengths(length_m: float, speed_mps: float, times_s: np.ndarray,
                          max_accel_mps2: float) -> np.ndarray:
    """Distances [len(times_s)] along a path of `length_m` at `times_s` (the last is the horizon
    T) for a vehicle now at `speed_mps`: s(t) = v t + a t² / 2 with a = 2 (L − v T) / T² capped at
    `max_accel_mps2`; if the speed would turn negative before T, uniform braking to a stop at L
    (s = v t − v² t² / (4 L) until t = 2 L / v). Never beyond L, never backwards."""
    v, horizon = max(float(speed_mps), 0.0), float(times_s[-1])
    if length_m <= 0.0:
        return np.zeros(len(times_s))
    accel = min(2.0 * (length_m - v * horizon) / horizon ** 2, max_accel_mps2)
    if v + accel * horizon >= 0.0:
        s = v * times_s + 0.5 * accel * times_s ** 2
    else:
        s = np.where(times_s < 2.0 * length_m / v, v * times_s - v * v * times_s ** 2 / (4.0 * length_m),
                     length_m)
    return np.clip(s, 0.0, length_m)


def retime(path_cells: np.ndarray, moves: int, grid: GridConfig, speed_mps: float,
           config: SamplerConfig, goal_xy: np.ndarray | None = None) -> np.ndarray:
    """[config.waypoints, 2] ego-frame waypoints along one cell path [N + 1, 2] (its first
    `moves` moves) at `kinematic_arc_lengths`.

    The path starts at the ego itself (the origin), not at its cell's centre: that centre lies up
    to half a cell away (0.6 m ahead on the US-101 grid), and a plan that starts there asks a
    standing ego to creep that far at every replan. Likewise a path that ends in the goal's cell
    ends at `goal_xy` (ego frame) rather than at that cell's centre, up to half a cell (1.8 m)
    away: on recorded traffic this took the open-loop final error towards the human's end from
    4.3 to 2.6 m (experiments/README.md)."""
    centres = ego_from_grid(path_cells[: moves + 1], grid)
    if tuple(grid_from_ego(np.zeros(2), grid)) == tuple(path_cells[0]):
        centres[0] = 0.0            # the path starts in the ego's cell: start at the ego
    if goal_xy is not None and moves > 0 and \
            tuple(grid_from_ego(np.asarray(goal_xy, float), grid)) == tuple(path_cells[moves]):
        centres[-1] = goal_xy       # it ends in the goal's cell: end at the goal itself
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(centres, axis=0), axis=1))])
    times = config.dt_s * np.arange(1, config.waypoints + 1)
    s = kinematic_arc_lengths(float(cum[-1]), speed_mps, times, config.max_accel_mps2)
    if len(centres) == 1:
        return np.repeat(centres, config.waypoints, axis=0)
    return np.column_stack([np.interp(s, cum, centres[:, 0]), np.interp(s, cum, centres[:, 1])])


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
                      config: SamplerConfig = SamplerConfig(), seed: int = 0,
                      speed_mps: float | None = None, goal_xy: np.ndarray | None = None) -> np.ndarray:
    """Waypoints [config.waypoints, 2] in the ego frame: the most central path of the largest
    cluster of `config.samples` sampled paths, timed by `config.timing` (`kinematic` needs the
    ego's `speed_mps`, and ends at the exact goal `goal_xy` when given and the path reaches its
    cell; without a speed the waypoints are uniform). Deterministic given `seed`."""
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
    members = np.flatnonzero(labels == largest)
    centre = flat[members].mean(axis=0)
    best = members[np.argmin(((flat[members] - centre) ** 2).sum(axis=1))]
    if config.timing == "kinematic" and speed_mps is not None:
        return retime(paths[best], int(lengths[best]), grid, speed_mps, config, goal_xy)
    return flat[best].reshape(config.waypoints, 2)
