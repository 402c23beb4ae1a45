"""Confidence intervals (reports, attack tables): Wilson intervals for rates, percentile bootstrap for
means; the sign test for paired outcomes (one planner against another on the same scenes)."""

from __future__ import annotations

import numpy as np

CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0      # fixed: the same records always give the same interval


def wilson(successes: int, trials: int) -> dict | None:
    """{value, lo, hi, k, n} of a rate with its Wilson score interval; None without trials."""
    if trials == 0:
        return None
    from scipy.stats import binomtest

    ci = binomtest(successes, trials).proportion_ci(CONFIDENCE, method="wilson")
    return {"value": successes / trials, "lo": float(ci.low), "hi": float(ci.high),
            "k": int(successes), "n": int(trials)}


def bootstrap_mean(values) -> dict | None:
    """{value, lo, hi, n, p90} of a mean with its percentile-bootstrap interval; None if empty."""
    x = np.asarray([v for v in values if v is not None], dtype=np.float64)
    if x.size == 0:
        return None
    mean = float(x.mean())
    out = {"value": mean, "lo": mean, "hi": mean, "n": int(x.size),
           "p90": float(np.percentile(x, 90))}
    if x.size >= 2 and np.ptp(x) > 0:
        from scipy.stats import bootstrap

        res = bootstrap((x,), np.mean, confidence_level=CONFIDENCE, n_resamples=BOOTSTRAP_RESAMPLES,
                        method="percentile", rng=np.random.default_rng(BOOTSTRAP_SEED))
        out["lo"], out["hi"] = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return out


def sign_test(a_only: int, b_only: int) -> float:
    """Two-sided sign test p-value of paired binary outcomes: `a_only` pairs where only A had the
    event, `b_only` where only B had it (ties carry no information); 1.0 with no discordant pair."""
    if a_only + b_only == 0:
        return 1.0
    from scipy.stats import binomtest

    return float(binomtest(a_only, a_only + b_only).pvalue)
