"""System 1 online: the trained TGAT scores (ego, neighbour) windows cut from a recording or Scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from rasterize.tracks import Tracks
from riskmap.guard.features import window_features
from riskmap.guard.tgat import TGAT, TGATConfig

CHECKPOINT_KIND = "guard_tgat"


class AccidentPredictor:
    def __init__(self, model: TGAT, alert_threshold: float = 0.6):
        self.model, self.alert_threshold = model.eval(), float(alert_threshold)

    @classmethod
    def load(cls, path: str | Path) -> AccidentPredictor:
        from riskmap.infra.checkpoint import load_weights, read_sidecar, sidecar_section

        side = read_sidecar(Path(path), kind=CHECKPOINT_KIND)   # missing, damaged, other kind
        model = load_weights(TGAT(sidecar_section(side, "model", path, TGATConfig)), Path(path),
                             "train it again with `riskmap guard train` or use checkpoints/guard_tgat")
        return cls(model, side["alert_threshold"])

    @torch.no_grad()
    def score(self, tracks: Tracks, ego: int, neighbours: list[int], last_step: int, segment_steps: int
              ) -> tuple[np.ndarray, np.ndarray]:
        """(accident probabilities, times to contact in s), each [len(neighbours)], of the windows
        ending at `last_step` (`tracks` as `riskmap.guard.features.window_features`)."""
        if not neighbours:
            return np.zeros(0), np.zeros(0)
        parts = [window_features(tracks, ego, i, last_step, segment_steps) for i in neighbours]
        tensors = [torch.from_numpy(np.stack([p[k] for p in parts])) for k in range(4)]
        logits, ttc = self.model(tensors[0].float(), tensors[1].float(), tensors[2].float(), tensors[3].bool())
        return torch.sigmoid(logits).numpy().astype(np.float64), ttc.numpy().astype(np.float64)
