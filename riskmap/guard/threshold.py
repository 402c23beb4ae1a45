"""The alert threshold, chosen on validation decision frames for a target alert ratio.

The guard alerts in a decision frame when the highest score of the windows it scores there (the
nearest neighbours) reaches the threshold. On the validation episodes' frames
(`riskmap.guard.dataset.load_frames`) the threshold is set just above the k-th highest frame
score, k = ⌊ratio · frames⌋, so that at most that share of the frames alerts: the intervention
budget is fixed first and the predictor's ranking decides where it is spent.
"""

from __future__ import annotations

import numpy as np


def frame_max_scores(window_scores: np.ndarray, frame: np.ndarray, frames: int) -> np.ndarray:
    """Highest score per frame [frames] (0 where a frame scored no window); window_scores [M],
    frame [M] the frame each window belongs to."""
    best = np.zeros(frames, np.float64)
    np.maximum.at(best, np.asarray(frame, dtype=np.int64), np.asarray(window_scores, dtype=np.float64))
    return best


def threshold_for_ratio(frame_scores: np.ndarray, ratio: float) -> float:
    """The smallest threshold t with mean(frame_scores ≥ t) ≤ ratio (ties stay below it)."""
    scores = np.sort(np.asarray(frame_scores, dtype=np.float64))[::-1]
    k = int(np.floor(ratio * len(scores) + 1e-9))   # ratio·n exact in reals may round just below
    if k >= len(scores):
        return 0.0
    return float(np.nextafter(scores[k], np.inf))


def alert_ratio(frame_scores: np.ndarray, threshold: float) -> float:
    scores = np.asarray(frame_scores, dtype=np.float64)
    return float((scores >= threshold).mean()) if len(scores) else 0.0
