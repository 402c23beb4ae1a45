"""Binary classification metrics over a whole split (sklearn)."""

from __future__ import annotations

import numpy as np
from sklearn.metrics import accuracy_score, average_precision_score, f1_score, roc_auc_score


def binary_metrics(labels: np.ndarray, probs: np.ndarray, threshold: float) -> dict:
    """AP and AUC of the scores, accuracy and F1 of `probs >= threshold`, and the split's size.
    AP/AUC are None when the split holds a single class (they are undefined then)."""
    labels = np.asarray(labels).astype(int)
    probs = np.asarray(probs, dtype=np.float64)
    both = 0 < labels.sum() < len(labels)
    predicted = (probs >= threshold).astype(int)
    return {"n": len(labels), "positives": int(labels.sum()), "threshold": threshold,
            "ap": float(average_precision_score(labels, probs)) if both else None,
            "auc": float(roc_auc_score(labels, probs)) if both else None,
            "accuracy": float(accuracy_score(labels, predicted)),
            "f1": float(f1_score(labels, predicted, zero_division=0))}
