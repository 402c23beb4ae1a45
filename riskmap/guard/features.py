"""Features of one (ego, neighbour) interaction window, shared by the dataset and the online guard.

A window is 8 time segments of `segment` record steps: segments 1–6 are observed interaction
events, segment 7 is not observed, and segment 8 is the virtual target whose edge feature is zero
(the model asks "do these two collide by then?"). Node features are taken at the last observed
segment and held for the whole window, as in the TGAT formulation.

Shapes (one window): node [NODE_DIM], edge [OBSERVED, EDGE_DIM], mask [OBSERVED] (True where
the event exists: both vehicles present at that time).
"""

from __future__ import annotations

import numpy as np

from rasterize.scene import AgentKind
from riskmap.guard.events import projected_separation

OBSERVED = 6          # observed segments
TARGET_SEGMENT = 8    # index (1-based) of the virtual target segment
SEGMENT_S = 0.5       # seconds per segment
NODE_DIM = 6          # length, width (m), speed (m/s), cos, sin of heading relative to the ego, is-vehicle
EDGE_DIM = 1          # d_s (m)
# Event times of segments 1..6 and of the target, seconds from the start of the window.
EVENT_TIMES_S = SEGMENT_S * np.arange(1, OBSERVED + 1, dtype=np.float64)
TARGET_TIME_S = SEGMENT_S * TARGET_SEGMENT
HORIZON_S = TARGET_TIME_S - EVENT_TIMES_S[-1]   # a collision within this after the last event is positive


def _yaw(states: np.ndarray) -> np.ndarray:
    return np.arctan2(states[..., 3], states[..., 2])


def node_features(states: np.ndarray, sizes: np.ndarray, kinds: np.ndarray, agent: int, ego: int,
                  step: int) -> np.ndarray:
    """[NODE_DIM] of `agent` at `step`; headings relative to the ego's so the frame does not matter."""
    rel = _yaw(states[agent, step]) - _yaw(states[ego, step])
    return np.array([sizes[agent, 0], sizes[agent, 1], states[agent, step, 4], np.cos(rel), np.sin(rel),
                     float(kinds[agent] == AgentKind.VEHICLE)], dtype=np.float32)


def window_features(states: np.ndarray, valid: np.ndarray, sizes: np.ndarray, kinds: np.ndarray,
                    ego: int, neighbour: int, last_step: int, segment_steps: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(node_u, node_i, edge, mask) of the window whose last observed event is at `last_step`.

    states [A, S, 6], valid [A, S], sizes [A, 2], kinds [A] (a recording or a Scene's arrays);
    the events are at last_step − segment_steps·(5, 4, ..., 0).
    """
    steps = last_step - segment_steps * np.arange(OBSERVED - 1, -1, -1)
    inside = steps >= 0
    safe = np.where(inside, steps, 0)
    mask = inside & valid[ego, safe] & valid[neighbour, safe]
    su, si = states[ego, safe], states[neighbour, safe]
    ds = projected_separation(su[:, :2], _yaw(su), sizes[ego], si[:, :2], _yaw(si), sizes[neighbour])
    edge = np.where(mask, ds, 0.0).astype(np.float32)[:, None]
    return (node_features(states, sizes, kinds, ego, ego, last_step),
            node_features(states, sizes, kinds, neighbour, ego, last_step), edge, mask)
