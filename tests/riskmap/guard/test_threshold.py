"""The alert threshold for a target alert ratio, against brute force over candidate thresholds."""

import numpy as np
import pytest

from riskmap.guard.threshold import alert_ratio, frame_max_scores, threshold_for_ratio


def brute_force_threshold(scores: np.ndarray, ratio: float) -> float:
    """The smallest t among the candidates (every score, and the next float above every score:
    the ratio only changes there) with mean(scores ≥ t) ≤ ratio."""
    scores = np.asarray(scores, dtype=np.float64)
    candidates = sorted(set(scores.tolist()) | set(np.nextafter(scores, np.inf).tolist()))
    return min(t for t in candidates if np.mean(scores >= t) <= ratio)


def _scores(rng, n):
    # coarse values: many ties, as frame maxima of a saturated predictor have
    return np.round(rng.uniform(0, 1, n), 1) if rng.uniform() < 0.5 else rng.uniform(0, 1, n)


def test_threshold_for_ratio_matches_brute_force_with_ties():
    rng = np.random.default_rng(0)
    for trial in range(300):
        n = int(rng.integers(1, 60))
        scores = _scores(rng, n)
        # ratios strictly between the multiples of 1/n (see the boundary test below)
        ratio = (int(rng.integers(0, n)) + float(rng.uniform(0.05, 0.95))) / n
        t = threshold_for_ratio(scores, ratio)
        assert t == brute_force_threshold(scores, ratio), (trial, n, ratio)
        assert alert_ratio(scores, t) <= ratio
        # any lower candidate alerts on more than the target share
        lower = [c for c in np.concatenate([scores, np.nextafter(scores, np.inf)]) if c < t]
        assert all(np.mean(scores >= c) > ratio for c in lower), (trial, n, ratio)


def test_threshold_for_ratio_hand_computed():
    scores = np.array([0.9, 0.8, 0.8, 0.8, 0.3, 0.1, 0.1, 0.1, 0.1, 0.1])
    # 10 %: one frame may alert: just above the second highest (0.8)
    assert threshold_for_ratio(scores, 0.1) == np.nextafter(0.8, 1.0)
    # 30 %: three may, but 0.8 is tied three times: a threshold at 0.8 alerts 4 → stay above it
    assert threshold_for_ratio(scores, 0.3) == np.nextafter(0.8, 1.0)
    assert alert_ratio(scores, threshold_for_ratio(scores, 0.3)) == 0.1
    # 45 %: four may: just above 0.3
    assert threshold_for_ratio(scores, 0.45) == np.nextafter(0.3, 1.0)
    assert alert_ratio(scores, np.nextafter(0.3, 1.0)) == 0.4
    # below 1/n no frame may alert
    assert threshold_for_ratio(scores, 0.05) == np.nextafter(0.9, 1.0)
    assert alert_ratio(scores, threshold_for_ratio(scores, 0.05)) == 0.0


def test_threshold_for_ratio_at_an_exact_multiple_of_one_over_n():
    scores = np.linspace(0.0, 0.99, 100)          # distinct
    ratio = 0.29                                  # 29 / 100 == 0.29 in floating point
    assert 29 / 100 == ratio
    t = threshold_for_ratio(scores, ratio)
    assert alert_ratio(scores, t) == pytest.approx(0.29)
    assert t == brute_force_threshold(scores, ratio)


def test_alert_ratio_counts_scores_at_or_above():
    scores = np.array([0.2, 0.6, 0.6, 0.9])
    assert alert_ratio(scores, 0.6) == 0.75
    assert alert_ratio(scores, np.nextafter(0.6, 1.0)) == 0.25
    assert alert_ratio(np.zeros(0), 0.5) == 0.0


def test_frame_max_scores_matches_a_python_loop():
    rng = np.random.default_rng(1)
    for _ in range(20):
        frames = int(rng.integers(1, 30))
        m = int(rng.integers(0, 3 * frames))
        frame = rng.integers(0, frames, m)
        scores = rng.uniform(0, 1, m).astype(np.float32)
        ref = [0.0] * frames                      # a frame without windows scores 0
        for f, s in zip(frame.tolist(), scores.tolist()):
            ref[f] = max(ref[f], float(s))
        out = frame_max_scores(scores, frame, frames)
        assert out.dtype == np.float64 and out.shape == (frames,)
        np.testing.assert_array_equal(out, np.array(ref))
