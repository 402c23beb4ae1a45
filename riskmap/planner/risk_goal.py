"""A goal the risk map can pull back: the route rule's goal, shortened to just before the first
point of the route where the predicted reward falls below a threshold.

Why: the planner is pulled to its goal by value iteration, and the speed it then drives comes
from the plan's length. With the route rule's goal alone (`rasterize.highway.RouteRule`: as far
as the ego could get in 6 s, capped behind a leader on the route) a vehicle cutting in from the
next lane never shortens the plan, whatever the risk map says about it; and a demonstration that
brakes for it ends tens of metres short of the goal, which no risk map can explain (the route goal
lay a median 38.5 m beyond the end of the attack windows' demonstrations, 15.4 m in natural ones,
experiments/README.md "Hardening"). Here the risk map itself decides where the route is blocked,
the same rule in training (goal maps from the model's own, detached risk map) and in closed loop,
so the map can learn to brake the ego.

Shapes: reward [G, G] (the model's output, higher is better: reward = −cost); route cells
[P, 2] (row, col) every `rasterize.maps.ROUTE_STEP_M` from the ego to the route rule's goal,
padded with −1 (`rasterize.maps.route_cells`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.errors import InputError
from rasterize.maps import ROUTE_STEP_M


@dataclass(frozen=True)
class RiskGoalConfig:
    """`threshold`: reward (risk-map units) below which a route point is blocked; on the highway
    checkpoint lane cells on the route sit at a median −1.9 and cells under other vehicles at a
    median −6.5. `skip_m`: route points nearer than this (m, along the route) are not checked —
    the ego's own footprint. `reach_s`: only the stretch the ego would cover in this long at its
    present speed (beyond `skip_m`) is checked — the risk map is a map of the present, so a car
    50 m ahead that will have moved on by the time the ego gets there must not hold the goal back
    (the route rule already follows a leader). `half_width_cells`: cells either side of the
    route's cell that the ego's footprint covers. `margin_m`: the goal is held this far (m) short
    of the blocked point, but never nearer than `min_goal_m` nor than the distance the ego needs
    to stop braking at `brake_mps2`: a goal at the ego's bumper gives the controller waypoints
    beside it, and it swerves (seen off the road within 0.5 s in natural traffic).
    `goal_variance`: cells², of a held-back goal's map. It must be narrow: with the route goal's
    5 cells² value iteration stops where one more cell towards the goal gains less than it costs,
    (2d − 1)/(2σ²) < |r|, about 18 cells short at the −3.5 per cell near the ego, so a goal 7
    cells ahead made the policy end where it stands."""

    threshold: float = -6.0
    skip_m: float = 8.0
    reach_s: float = 1.5
    half_width_cells: int = 0
    margin_m: float = 5.0
    min_goal_m: float = 10.0
    brake_mps2: float = 6.0
    goal_variance: float = 0.5

    def __post_init__(self) -> None:
        if self.brake_mps2 <= 0 or self.goal_variance <= 0:
            raise InputError(f"risk goal brake_mps2 and goal_variance must be positive, got {self}")
        if min(self.skip_m, self.margin_m, self.reach_s, self.half_width_cells, self.min_goal_m) < 0:
            raise InputError(f"risk goal settings must be non-negative, got {self}")


def risk_goal_cell(reward: np.ndarray, cells: np.ndarray, speed_mps: float,
                   config: RiskGoalConfig) -> tuple[int, int] | None:
    """The goal cell held `margin_m` short of the first blocked point of the route (no nearer than
    `min_goal_m` and the stopping distance), or None where the checked stretch is clear or the
    held-back goal would not be nearer than the route rule's (the route rule's goal stands).

    A point is blocked when its footprint (its cell and `half_width_cells` either side, the
    lowest reward) is below `threshold`; checked are the points between `skip_m` and
    `skip_m + speed × reach_s` along the route."""
    cells = cells[cells[:, 0] >= 0]
    if len(cells) == 0:
        return None
    w = config.half_width_cells
    cols = np.clip(cells[:, 1:2] + np.arange(-w, w + 1)[None], 0, reward.shape[1] - 1)   # [P, 2w+1]
    footprint = reward[cells[:, :1], cols].min(axis=1)                                  # [P]
    along = ROUTE_STEP_M * np.arange(len(cells))
    checked = (along >= config.skip_m) & (along <= config.skip_m + max(speed_mps, 0.0) * config.reach_s)
    hit = np.flatnonzero((footprint < config.threshold) & checked)
    if hit.size == 0:
        return None
    speed = max(speed_mps, 0.0)
    floor_m = max(config.min_goal_m, speed * speed / (2.0 * config.brake_mps2))
    k = max(int(hit[0]) - round(config.margin_m / ROUTE_STEP_M), int(np.ceil(floor_m / ROUTE_STEP_M)))
    if k >= len(cells) - 1:
        return None
    r, c = cells[k]
    return int(r), int(c)


def risk_goal_cells(reward: np.ndarray, cells: np.ndarray, speed_mps: np.ndarray,
                    goal_cells: np.ndarray, route_variance: float, config: RiskGoalConfig
                    ) -> tuple[np.ndarray, np.ndarray]:
    """`risk_goal_cell` over a batch: ([B, 2] goal cells, [B] goal variances): the route rule's
    `goal_cells` [B, 2] and `route_variance` where the route is clear, else the held-back cell and
    `config.goal_variance`. reward [B, G, G], cells [B, P, 2], speed_mps [B]."""
    out = np.array(goal_cells, dtype=np.int64, copy=True)
    variance = np.full(len(out), float(route_variance))
    for i in range(len(out)):
        limited = risk_goal_cell(reward[i], cells[i], float(speed_mps[i]), config)
        if limited is not None:
            out[i], variance[i] = limited, config.goal_variance
    return out, variance
