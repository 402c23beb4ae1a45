"""`riskmap guard evaluate`: score a trained TGAT checkpoint on any splits of a guard dataset.

For comparing checkpoints on the same windows (e.g. before and after adding the adversary's
accident windows to the training data, `adversary guard-data`): metrics over each whole split,
accuracy and F1 at 0.5 and at the checkpoint's alert threshold, and the time-to-contact error,
as `riskmap guard train` reports them; windows are labelled for the checkpoint's horizon.
"""

from __future__ import annotations

from pathlib import Path

from riskmap.guard.dataset import load_split
from riskmap.guard.predictor import AccidentPredictor
from riskmap.guard.train import _tensors, evaluate


def evaluate_checkpoint(checkpoint: Path, data: Path, splits: list[str]) -> dict:
    """{split: metrics} of the checkpoint (a path without suffix) on every split of `data`."""
    predictor = AccidentPredictor.load(checkpoint)
    horizon_s = predictor.model.config.horizon_s
    return {split: evaluate(predictor.model, _tensors(load_split(data, split, horizon_s)),
                            predictor.alert_threshold) for split in splits}
