"""Trajectory sampler (planner paper §IV-C): paths sampled from the policy, clustered, the largest
cluster's most central path turned into 12 ego-frame waypoints over 6 s.

Shapes: policy [5, H, W] of one scene; paths [S, N + 1, 2] cells (row, col) with lengths [S]
(number of moves); waypoints [12, 2] ego-frame metres (x forward, y left).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch

from rasterize.config import GridConfig
from rasterize.errors import InputError
from rasterize.frames import ego_from_grid, grid_from_ego
from riskmap.planner.vi import END, MOVES

TIMINGS = ("uniform", "kinematic", "learned")


@dataclass(frozen=True)
class SamplerConfig:
    """`timing`: how the chosen path is spread over the 6 s. `uniform`: waypoints evenly spaced
    in distance (constant speed from the start, whatever the ego's speed now); `kinematic`: the
    ego's current speed, changed at the one constant acceleration that ends the path at 6 s
    (at most `max_accel_mps2`; where that would mean reversing, braking to a stop at its end):
    `kinematic_arc_lengths`; `learned`: the arc lengths the network's timing head predicts
    (`riskmap.planner.model.TimingHead`), never beyond the path's end. Checkpoints from before
    `timing` existed plan `uniform` (their sidecars are upgraded so: `riskmap.infra.checkpoint`)."""

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
           config: SamplerConfig, goal_xy: np.ndarray | None = None,
           arc_lengths: np.ndarray | None = None) -> np.ndarray:
    """[config.waypoints, 2] ego-frame waypoints along one cell path [N + 1, 2] (its first
    `moves` moves) at `kinematic_arc_lengths`, or at `arc_lengths` [config.waypoints] (metres,
    non-decreasing) where given, each held at the path's end if beyond it.

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
    if arc_lengths is None:
        s = kinematic_arc_lengths(float(cum[-1]), speed_mps, times, config.max_accel_mps2)
    else:
        s = np.clip(np.maximum.accumulate(np.asarray(arc_lengths, float)), 0.0, float(cum[-1]))
    if len(centres) == 1:
        return np.repeat(centres, config.waypoints, axis=0)
    return np.column_stack([np.interp(s, cum, centres[:, 0]), np.interp(s, cum, centres[:, 1])])


def _walk(policy: torch.Tensor, start: tuple[int, int], horizon: int, samples: int,
          generator: torch.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The paths as flat cell indices row * W + col, (cells [S, N + 1], moves [S]), N the
    longest path's moves.

    Inverse-CDF sampling with all uniforms drawn at once from `generator`: an action is the
    number of the policy's first four cumulative probabilities at or below the draw (4 = end; the
    policy rows sum to 1, so the last bin takes any rounding remainder). A path that has ended
    moves to an absorbing index H * W whose thresholds are all 0, so every later draw ends it
    again: no per-path bookkeeping in the loop. The four comparisons of a path are four bytes,
    counted at once by reading them as one 32-bit word times 0x01010101 (its top byte is their
    sum): a step is a handful of numpy calls on 1000-element arrays.
    """
    _, h, w = policy.shape
    ended = h * w
    cdf = policy.detach().cpu().permute(1, 2, 0).reshape(h * w, 5).double().cumsum(dim=1).numpy()
    thresholds = np.concatenate([cdf[:, :END], np.zeros((1, END))])      # [H W + 1, 4]
    step = np.array([MOVES[a][0] * w + MOVES[a][1] for a in range(END)] + [0], dtype=np.int64)
    uniforms = torch.rand((horizon, samples, 1), generator=generator, dtype=torch.float64).numpy()
    flat = np.empty((horizon + 1, samples), dtype=np.int64)               # step-major while walking
    flat[0] = start[0] * w + start[1]
    last = horizon
    for t in range(horizon):
        below = uniforms[t] >= np.take(thresholds, flat[t], axis=0)      # [S, 4] bool
        action = (below.view(np.uint32)[:, 0] * np.uint32(0x01010101)) >> np.uint32(24)
        np.add(flat[t], step[action], out=flat[t + 1])
        flat[t + 1][action == END] = ended
        if (flat[t + 1] == ended).all():
            last = t + 1
            break
    flat = flat[: last + 1].T
    moves = (flat != ended).sum(axis=1) - 1
    end_cell = flat[np.arange(samples), moves]
    return np.where(flat == ended, end_cell[:, None], flat), moves


def sample_paths(policy: torch.Tensor, start: tuple[int, int], horizon: int, samples: int,
                 generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """All `samples` paths in one vectorised pass: (cells [S, horizon + 1, 2], moves [S]); a
    path stays in its last cell after it ends. Draws as `_walk`."""
    _, _, w = policy.shape
    flat, moves = _walk(policy, start, horizon, samples, generator)
    flat = np.concatenate([flat, np.repeat(flat[:, -1:], horizon + 1 - flat.shape[1], axis=1)], axis=1)
    return torch.from_numpy(np.stack([flat // w, flat % w], axis=-1)), torch.from_numpy(moves)


@lru_cache(maxsize=16)
def _cell_centres(grid: GridConfig) -> np.ndarray:
    """Ego-frame centre of every cell, by flat index [H W, 2] (`ego_from_grid`, computed once)."""
    rows, cols = np.divmod(np.arange(grid.rows * grid.cols), grid.cols)
    return ego_from_grid(np.stack([rows, cols], axis=-1), grid)


def downsample(paths: np.ndarray, moves: np.ndarray, count: int, grid: GridConfig) -> np.ndarray:
    """[S, count, 2] waypoints (ego metres) evenly spaced in distance along each path, start
    excluded. paths [S, N + 1, 2] cells; moves [S] number of moves of each path.

    Spacing is by metres along the cell centres, not by cell count: highway cells are 4.8 m long
    and 0.8 m wide, and counting cells would make a lane change look like braking.
    """
    paths = np.asarray(paths)
    return _spaced(paths[..., 0] * grid.cols + paths[..., 1], np.asarray(moves), count, grid)


def _spaced(flat: np.ndarray, moves: np.ndarray, count: int, grid: GridConfig) -> np.ndarray:
    """`downsample` of paths given as flat cell indices [S, N + 1].

    A move is one cell along a row (`row_m` metres) or a column (`col_m`), so its length is
    looked up from the index difference (±W, ±1, or 0 where the path stands) instead of being
    measured between centres; only the 2 × count centres that bracket a waypoint are looked up."""
    w = grid.cols
    length_of = np.zeros(2 * w + 1)                           # by index difference + W
    length_of[[0, 2 * w]], length_of[[w - 1, w + 1]] = grid.row_m, grid.col_m
    step = length_of[np.diff(flat, axis=1) + w]                            # [S, N]
    step[np.arange(step.shape[1])[None, :] >= moves[:, None]] = 0.0        # beyond the end
    cum = np.zeros((len(step), step.shape[1] + 1))
    np.cumsum(step, axis=1, out=cum[:, 1:])
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
    centres = _cell_centres(grid)
    p_lo = centres[np.take_along_axis(flat, lo, 1)]
    p_hi = centres[np.take_along_axis(flat, hi, 1)]
    return p_lo + frac[..., None] * (p_hi - p_lo)


@lru_cache(maxsize=8)
def _projection(dimensions: int) -> np.ndarray:
    """A fixed random direction in `dimensions` dimensions (made once per width, not per plan)."""
    return np.random.default_rng(0).normal(size=dimensions)


def distinct_at_least(rows: np.ndarray, k: int) -> int:
    """min(k, number of distinct rows of `rows` [S, D]). Rows are first told apart by one random
    projection (a few microseconds for 1000 rows): equal rows project equally, so if k
    projections differ there are at least k distinct rows; only otherwise is the exact
    row-wise unique taken."""
    projected = rows @ _projection(rows.shape[1])
    if len(np.unique(projected)) >= k:
        return k
    return min(k, len(np.unique(rows, axis=0)))


def kmeans(points: np.ndarray, k: int, seed: int, max_iterations: int = 100,
           tolerance: float = 1e-4) -> np.ndarray:
    """Cluster labels [S] of `points` [S, D] (k ≤ number of distinct points): greedy k-means++
    seeding from `seed` (each new centre the best of 2 + ln k candidates drawn in proportion to
    the squared distance to the nearest centre so far, as scikit-learn seeds), then Lloyd's
    iterations until no label changes or the centres move less than `tolerance` × the points'
    mean variance (squared, summed over centres; scikit-learn's rule). An emptied cluster keeps
    its centre. Squared distances by the expansion |x|² − 2 x·c + |c|², so an iteration is two
    small matrix products."""
    rng = np.random.default_rng(seed)
    n = len(points)
    trials = 2 + int(np.log(k))
    centres = np.empty((k, points.shape[1]))
    norms = (points ** 2).sum(axis=1)
    twice = 2.0 * points
    centres[0] = points[rng.integers(n)]
    nearest = np.maximum(norms - twice @ centres[0] + centres[0] @ centres[0], 0.0)
    for j in range(1, k):
        cumulative = np.cumsum(nearest)
        picks = np.minimum(np.searchsorted(cumulative, rng.random(trials) * cumulative[-1],
                                           side="right"), n - 1)
        candidates = points[picks]                                          # [trials, D]
        to_candidates = norms[None, :] - candidates @ twice.T + (candidates ** 2).sum(axis=1)[:, None]
        potentials = np.minimum(nearest[None, :], np.maximum(to_candidates, 0.0))   # [trials, S]
        best = int(potentials.sum(axis=1).argmin())
        centres[j], nearest = candidates[best], potentials[best]
    threshold = tolerance * float(points.var(axis=0).mean())
    one_hot = np.eye(k, dtype=points.dtype)
    labels = np.full(n, -1)
    twice_t = np.ascontiguousarray(twice.T)           # [D, S]: distances come out [k, S]
    for _ in range(max_iterations):
        new = ((centres ** 2).sum(axis=1)[:, None] - centres @ twice_t).argmin(axis=0)
        if np.array_equal(new, labels):
            break
        labels = new
        counts = np.bincount(labels, minlength=k)
        filled = counts > 0
        moved = (one_hot[:, labels] @ points)[filled] / counts[filled, None]
        shift = float(((moved - centres[filled]) ** 2).sum())
        centres[filled] = moved
        if shift <= threshold:
            break
    return labels


def sample_trajectory(policy: torch.Tensor, start: tuple[int, int], horizon: int, grid: GridConfig,
                      config: SamplerConfig = SamplerConfig(), seed: int = 0,
                      speed_mps: float | None = None, goal_xy: np.ndarray | None = None,
                      arc_lengths: np.ndarray | None = None) -> np.ndarray:
    """Waypoints [config.waypoints, 2] in the ego frame: the most central path of the largest
    cluster of `config.samples` sampled paths, timed by `config.timing` (`kinematic` needs the
    ego's `speed_mps`, and ends at the exact goal `goal_xy` when given and the path reaches its
    cell; `learned` needs the timing head's `arc_lengths` [config.waypoints] m as well; without
    them the waypoints are uniform). Deterministic given `seed`."""
    generator = torch.Generator().manual_seed(seed)
    flat, moves = _walk(policy.detach().cpu(), start, horizon, config.samples, generator)
    # Represent each path by its own evenly spaced waypoints, then cluster those.
    feats = _spaced(flat, moves, config.waypoints, grid)
    flat_feats = feats.reshape(len(feats), -1)
    k = distinct_at_least(flat_feats, config.clusters)
    labels = kmeans(flat_feats, k, seed) if k > 1 else np.zeros(len(flat_feats), dtype=int)
    largest = np.bincount(labels).argmax()
    members = np.flatnonzero(labels == largest)
    centre = flat_feats[members].mean(axis=0)
    best = members[np.argmin(((flat_feats[members] - centre) ** 2).sum(axis=1))]
    learned = config.timing == "learned" and arc_lengths is not None
    if (config.timing == "kinematic" or learned) and speed_mps is not None:
        path = np.stack(np.divmod(flat[best], grid.cols), axis=-1)
        return retime(path, int(moves[best]), grid, speed_mps, config, goal_xy,
                      arc_lengths if learned else None)
    return flat_feats[best].reshape(config.waypoints, 2)
