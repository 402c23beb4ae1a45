"""Choosing the adversary among the ego's neighbours.

STRIVE's distance-based rule: roll the scene forward, take the distance d[i, t] of every other
agent i to the ego at each future time t, and weight the (agent, time) pairs by a softmin,

    w[i, t] = exp(-d[i, t] / tau) / sum_{j, s} exp(-d[j, s] / tau),

over agents that are not behind the ego now (their centre's forward coordinate in the ego frame
is >= 0). An agent's weight is sum_t w[i, t]; the adversary is the agent of largest weight.
`nearest` is the plain alternative: the agent nearest the ego now, behind or not.
"""

from __future__ import annotations

import copy

import numpy as np

from rasterize.errors import InputError


def softmin_agent_weights(distances_m: np.ndarray, eligible: np.ndarray, temperature_m: float
                          ) -> np.ndarray:
    """Agent weights [A] from future distances [A, T] (m); ineligible agents get weight 0."""
    distances_m = np.asarray(distances_m, dtype=np.float64)
    eligible = np.asarray(eligible, dtype=bool)
    if not temperature_m > 0:
        raise InputError(f"softmin temperature_m must be positive metres, got {temperature_m}")
    weights = np.zeros(distances_m.shape[0])
    if not eligible.any():
        return weights
    logits = -distances_m[eligible] / temperature_m
    logits -= logits.max()                          # stable: the largest term is exp(0)
    pair = np.exp(logits)
    weights[eligible] = pair.sum(axis=1) / pair.sum()
    return weights


def predict_positions(road, vehicles: list, horizon_s: float, step_s: float, sim_dt_s: float
                      ) -> np.ndarray:
    """Positions [len(vehicles), T, 2] (highway-env frame) at step_s, 2·step_s, ... horizon_s.

    Every vehicle follows its own behaviour model on a deep copy of the road; the live road is
    left untouched. Vehicles that leave the copy keep their last position.
    """
    twin = copy.deepcopy(road)
    index = {id(v): i for i, v in enumerate(road.vehicles)}
    twins = [twin.vehicles[index[id(v)]] for v in vehicles]
    sub_steps = round(step_s / sim_dt_s)
    out = np.zeros((len(vehicles), round(horizon_s / step_s), 2))
    for t in range(out.shape[1]):
        for _ in range(sub_steps):
            twin.act()
            twin.step(sim_dt_s)
        out[:, t] = [v.position for v in twins]
    return out


def select_adversary(road, ego, rule: str, temperature_m: float = 2.0, horizon_s: float = 6.0,
                     step_s: float = 0.5, sim_dt_s: float = 0.1, radius_m: float = 80.0):
    """The neighbour of `ego` that the rule picks (a vehicle on `road`), or None if there is none.

    Candidates are the other vehicles within `radius_m` of the ego now.
    """
    candidates = [v for v in road.vehicles
                  if v is not ego and np.linalg.norm(v.position - ego.position) <= radius_m]
    if not candidates:
        return None
    offsets = np.array([v.position - ego.position for v in candidates])
    if rule == "nearest":
        return candidates[int(np.argmin(np.linalg.norm(offsets, axis=1)))]
    if rule != "softmin":
        raise InputError(f"adversary selection rule {rule!r} is unknown; use softmin or nearest")
    forward = offsets @ np.array([np.cos(ego.heading), np.sin(ego.heading)])
    future = predict_positions(road, [ego] + candidates, horizon_s, step_s, sim_dt_s)
    distances = np.linalg.norm(future[1:] - future[:1], axis=2)
    weights = softmin_agent_weights(distances, forward >= 0.0, temperature_m)
    if not weights.any():
        return None
    return candidates[int(np.argmax(weights))]
