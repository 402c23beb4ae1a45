"""`riskmap guard evaluate`: score a trained TGAT checkpoint on any splits of a guard dataset.

For comparing checkpoints on the same windows (e.g. before and after adding the adversary's
accident windows to the training data, `adversary guard-data`): metrics over each whole split,
accuracy and F1 at 0.5 and at the checkpoint's alert threshold, as `riskmap guard train` reports
them.
"""

from __future__ import annotations

from pathlib import Path

from riskmap.guard.dataset import load_split
from riskmap.guard.metrics import binary_metrics
from riskmap.guard.predictor import AccidentPredictor
from riskmap.guard.train import _tensors, predict


def evaluate_checkpoint(checkpoint: Path, data: Path, splits: list[str]) -> dict:
    """{split: metrics} of the checkpoint (a path without suffix) on every split of `data`."""
    predictor = AccidentPredictor.load(checkpoint)
    out = {}
    for split in splits:
        tensors = _tensors(load_split(data, split))
        probs = predict(predictor.model, tensors)
        labels = tensors[4].numpy().astype(int)
        out[split] = {**binary_metrics(labels, probs, 0.5),
                      "at_alert_threshold": binary_metrics(labels, probs, predictor.alert_threshold)}
    return out
