"""Plans from a space-time policy: sampled paths are positions in time, so they are the waypoints.

Each of `samples` paths starts in the ego's cell and takes one action per step from the
time-indexed policy π_t (DESIGN §3b), giving its cell at every step t = 1 … T. A path becomes T
ego-frame points: the displacement of its cell's centre from the start cell's centre (the ego is
at the origin, up to half a cell from its cell's centre, and a displacement keeps a standing path
exactly where the ego stands). The paths are clustered (k-means on the T points, the spatial
sampler's `kmeans`) and the plan is the largest cluster's *mean*: its positions fall between cell
centres, so a cluster that moves 2 and 3 rows per step in equal parts plans the speed between.
No timing rule: when the ego is where is what the policy says. With T < 12 the 12 waypoints are
interpolated in time from the origin at t = 0.

Shapes: policy [T, A, G, G]; paths [S, T + 1] flat cell indices row · G + col; waypoints [12, 2].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from rasterize.config import GridConfig
from rasterize.frames import ego_from_grid
from riskmap.planner.sampler import distinct_at_least, kmeans
from riskmap.planner.st_vi import spacetime_actions
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS


@dataclass(frozen=True)
class SpaceTimeSamplerConfig:
    samples: int = 1000
    clusters: int = 10


def sample_spacetime_paths(policy: torch.Tensor | np.ndarray, start: tuple[int, int],
                           max_forward: int, max_across: int, samples: int,
                           generator: torch.Generator) -> np.ndarray:
    """[S, T + 1] flat cell indices of `samples` paths drawn from `policy` [T, A, G, G].

    Inverse-CDF sampling, all uniforms drawn at once from `generator`: the action of a path at
    step t is the number of the cumulative probabilities of its cell below its draw (the last
    bin takes any rounding remainder, and off-grid actions have probability 0, so their bins are
    empty: a drawn action always stays on the grid)."""
    policy = np.asarray(policy.detach().cpu() if isinstance(policy, torch.Tensor) else policy)
    steps, a, h, w = policy.shape
    actions = spacetime_actions(max_forward, max_across)
    if len(actions) != a:
        raise ValueError(f"policy has {a} actions, K={max_forward}, L={max_across} make {len(actions)}")
    shift = actions[:, 0] * w + actions[:, 1]
    flat_policy = policy.reshape(steps, a, h * w)
    uniforms = torch.rand((steps, samples, 1), generator=generator, dtype=torch.float64).numpy()
    flat = np.empty((samples, steps + 1), np.int64)
    flat[:, 0] = start[0] * w + start[1]
    for t in range(steps):
        # Only the cells some path is in: a few dozen, where the policy has thousands.
        cells, which = np.unique(flat[:, t], return_inverse=True)
        cdf = np.cumsum(flat_policy[t][:, cells].astype(np.float64), axis=0).T     # [U, A]
        # Once a cell's cumulative probability has reached 1 (up to rounding), the actions after
        # it (off the grid, or under 1e-12 together) are never drawn: thresholds above any draw.
        cdf[cdf >= cdf[:, -1:] - 1e-12] = 2.0
        action = (uniforms[t] >= cdf[which, :-1]).sum(axis=1)
        flat[:, t + 1] = flat[:, t] + shift[action]
    return flat


def path_displacements(flat: np.ndarray, grid: GridConfig) -> np.ndarray:
    """[S, T, 2] ego-frame metres: each step's cell centre minus the start cell's centre."""
    cells = np.stack(np.divmod(flat, grid.cols), axis=-1)
    centres = ego_from_grid(cells, grid)
    return centres[:, 1:] - centres[:, :1]


def to_plan_steps(points: np.ndarray) -> np.ndarray:
    """[12, 2] waypoints at 0.5 s from T points [T, 2] at 6 s / T (linear in time from the
    origin at t = 0; the identity for T = 12)."""
    steps = len(points)
    if steps == PLAN_STEPS:
        return points
    times = np.arange(steps + 1) * (PLAN_STEPS * PLAN_DT_S / steps)
    knots = np.concatenate([np.zeros((1, 2)), points])
    plan_times = PLAN_DT_S * np.arange(1, PLAN_STEPS + 1)
    return np.column_stack([np.interp(plan_times, times, knots[:, i]) for i in range(2)])


def spacetime_plan(policy: torch.Tensor | np.ndarray, start: tuple[int, int], grid: GridConfig,
                   max_forward: int, max_across: int,
                   config: SpaceTimeSamplerConfig = SpaceTimeSamplerConfig(), seed: int = 0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(waypoints [12, 2] ego metres, the chosen cluster's paths [M, T + 1] flat cells): the
    largest cluster's mean. Deterministic given `seed`."""
    generator = torch.Generator().manual_seed(seed)
    flat = sample_spacetime_paths(policy, start, max_forward, max_across, config.samples, generator)
    points = path_displacements(flat, grid)
    features = points.reshape(len(points), -1)
    k = distinct_at_least(features, config.clusters)
    labels = kmeans(features, k, seed) if k > 1 else np.zeros(len(features), dtype=int)
    members = np.flatnonzero(labels == np.bincount(labels).argmax())
    return to_plan_steps(points[members].mean(axis=0)), flat[members]
