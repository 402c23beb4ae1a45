"""Features of one (ego, neighbour) interaction window, shared by the dataset and the online guard.

A window is 6 observed interaction events, one per time segment of `segment` record steps (0.5 s),
and a virtual target event `horizon_s` after the last observed one whose edge feature is zero (the
model asks "do these two touch by then?"; the guard paper's window is horizon 1 s: segment 7
unobserved, segment 8 the target). Node features are taken at the last observed segment and held
for the whole window, as in the TGAT formulation. An edge carries the projected separation d_s and
the neighbour's position and velocity relative to the ego, in the ego's frame at that event: d_s
alone cannot tell a car closing in from one drifting away.

Shapes (one window): node [NODE_DIM], edge [OBSERVED, EDGE_DIM], mask [OBSERVED] (True where
the event exists: both vehicles present at that time).
"""

from __future__ import annotations

import numpy as np

from rasterize.scene import AgentKind
from rasterize.tracks import Tracks
from riskmap.guard.events import projected_separation

OBSERVED = 6          # observed segments
SEGMENT_S = 0.5       # seconds per segment
NODE_DIM = 6          # length, width (m), speed (m/s), cos, sin of heading relative to the ego, is-vehicle
EDGE_DIM = 5          # d_s (m); neighbour − ego position x, y (m) and velocity x, y (m/s), ego frame
# Event times of segments 1..6, seconds from the start of the window.
EVENT_TIMES_S = SEGMENT_S * np.arange(1, OBSERVED + 1, dtype=np.float64)
HORIZONS_S = (1.0, 2.0, 3.0)    # label horizons the data supports: contact within this after the last event
MAX_HORIZON_S = max(HORIZONS_S)


def _yaw(states: np.ndarray) -> np.ndarray:
    return np.arctan2(states[..., 3], states[..., 2])


def node_features(states: np.ndarray, sizes: np.ndarray, kinds: np.ndarray, agent: int, ego: int,
                  step: int) -> np.ndarray:
    """[NODE_DIM] of `agent` at `step`; headings relative to the ego's so the frame does not matter."""
    rel = _yaw(states[agent, step]) - _yaw(states[ego, step])
    return np.array([sizes[agent, 0], sizes[agent, 1], states[agent, step, 4], np.cos(rel), np.sin(rel),
                     float(kinds[agent] == AgentKind.VEHICLE)], dtype=np.float32)


def target_time_s(horizon_s: float) -> float:
    """The virtual target event's time, seconds from the start of the window."""
    return float(EVENT_TIMES_S[-1]) + horizon_s


def relative_motion(su: np.ndarray, si: np.ndarray) -> np.ndarray:
    """[..., 4]: the neighbour's position and velocity minus the ego's, rotated into the ego's
    frame (x along its heading); states [..., 6] as `rasterize.scene`."""
    heading = su[..., 2:4] / np.maximum(np.linalg.norm(su[..., 2:4], axis=-1, keepdims=True), 1e-9)
    left = np.stack([-heading[..., 1], heading[..., 0]], axis=-1)
    dp = si[..., :2] - su[..., :2]
    dv = si[..., 2:4] * si[..., 4:5] - su[..., 2:4] * su[..., 4:5]
    return np.stack([(dp * heading).sum(-1), (dp * left).sum(-1), (dv * heading).sum(-1), (dv * left).sum(-1)],
                    axis=-1)


def window_features(tracks: Tracks, ego: int, neighbour: int, last_step: int, segment_steps: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(node_u, node_i, edge, mask) of the window whose last observed event is at `last_step`.

    `tracks`: a recording's, or a Scene's arrays as `Tracks`; the events are at
    last_step − segment_steps·(5, 4, ..., 0).
    """
    states, valid, sizes, kinds = tracks.states, tracks.valid, tracks.sizes, tracks.kinds
    steps = last_step - segment_steps * np.arange(OBSERVED - 1, -1, -1)
    inside = steps >= 0
    safe = np.where(inside, steps, 0)
    mask = inside & valid[ego, safe] & valid[neighbour, safe]
    su, si = states[ego, safe], states[neighbour, safe]
    ds = projected_separation(su[:, :2], _yaw(su), sizes[ego], si[:, :2], _yaw(si), sizes[neighbour])
    edge = np.concatenate([ds[:, None], relative_motion(su, si)], axis=1)
    edge = np.where(mask[:, None], edge, 0.0).astype(np.float32)
    return (node_features(states, sizes, kinds, ego, ego, last_step),
            node_features(states, sizes, kinds, neighbour, ego, last_step), edge, mask)
