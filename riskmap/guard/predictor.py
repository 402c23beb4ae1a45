"""System 1 online: the trained TGAT scores (ego, neighbour) windows cut from a recording or Scene."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from rasterize.errors import InputError
from riskmap.guard.features import window_features
from riskmap.guard.tgat import TGAT, TGATConfig

CHECKPOINT_KIND = "guard_tgat"


class AccidentPredictor:
    def __init__(self, model: TGAT, alert_threshold: float = 0.6):
        self.model, self.alert_threshold = model.eval(), float(alert_threshold)

    @classmethod
    def load(cls, path: str | Path) -> AccidentPredictor:
        from safetensors.torch import load_file

        path = Path(path)
        weights, sidecar = path.with_suffix(".safetensors"), path.with_suffix(".json")
        if not weights.exists() or not sidecar.exists():
            raise InputError(f"guard checkpoint {path} not found (need {weights.name} and {sidecar.name}); "
                             "train one with `riskmap guard train` or use checkpoints/guard_tgat")
        side = json.loads(sidecar.read_text())
        if side.get("kind") != CHECKPOINT_KIND:
            raise InputError(f"{sidecar} is not a guard TGAT checkpoint (kind={side.get('kind')})")
        model = TGAT(TGATConfig(**side["model"]))
        try:
            model.load_state_dict(load_file(str(weights)))
        except (RuntimeError, OSError) as err:
            raise InputError(f"guard checkpoint {path} does not match its config ({err})") from None
        return cls(model, side.get("alert_threshold", 0.6))

    @torch.no_grad()
    def score(self, states: np.ndarray, valid: np.ndarray, sizes: np.ndarray, kinds: np.ndarray, ego: int,
              neighbours: list[int], last_step: int, segment_steps: int) -> np.ndarray:
        """Accident probabilities [len(neighbours)] of the windows ending at `last_step`
        (arrays as `riskmap.guard.features.window_features`)."""
        if not neighbours:
            return np.zeros(0)
        parts = [window_features(states, valid, sizes, kinds, ego, i, last_step, segment_steps)
                 for i in neighbours]
        tensors = [torch.from_numpy(np.stack([p[k] for p in parts])) for k in range(4)]
        logits = self.model(tensors[0].float(), tensors[1].float(), tensors[2].float(), tensors[3].bool())
        return torch.sigmoid(logits).numpy().astype(np.float64)
