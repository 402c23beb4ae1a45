"""Checkpoints: safetensors weights plus a JSON sidecar with every config and the metrics."""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors.torch import load_file, save

from rasterize.errors import InputError
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.provenance import provenance

CHECKPOINT_KIND = "riskmap"


def save_checkpoint(path: Path, model: torch.nn.Module, sidecar: dict,
                    kind: str = CHECKPOINT_KIND) -> Path:
    """Write `path` (.safetensors) and `path.with_suffix('.json')`, each atomically.

    `kind` tags the sidecar so that a loader refuses weights of another model family.
    """
    path = Path(path).with_suffix(".safetensors")
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    atomic_write(path, lambda f: f.write(save(state)))
    write_json(path.with_suffix(".json"), {"kind": kind, **provenance(), **sidecar})
    return path


def read_sidecar(path: Path, kind: str = CHECKPOINT_KIND) -> dict:
    path = Path(path)
    weights = path.with_suffix(".safetensors")
    sidecar = path.with_suffix(".json")
    if not weights.exists() or not sidecar.exists():
        raise InputError(f"checkpoint {path} not found (need {weights.name} and {sidecar.name}); "
                         "train one with `riskmap train` or pass a path under checkpoints/")
    try:
        data = json.loads(sidecar.read_text())
    except ValueError:
        raise InputError(f"{sidecar} is not valid JSON; the checkpoint is damaged") from None
    if not isinstance(data, dict) or "kind" not in data:
        raise InputError(f"{sidecar} is not a checkpoint sidecar (it names no kind); pass the .json "
                         "that training wrote beside the .safetensors")
    if data["kind"] != kind:
        raise InputError(f"{sidecar} is a {data['kind']!r} checkpoint, not {kind!r}; pass a "
                         "checkpoint made for this planner")
    return data


def load_weights(model: torch.nn.Module, path: Path, fix: str) -> torch.nn.Module:
    """Load `path`.safetensors into `model` (eval mode); a mismatch is an InputError ending in `fix`."""
    try:
        model.load_state_dict(load_file(str(Path(path).with_suffix(".safetensors"))))
    except (RuntimeError, OSError) as err:
        raise InputError(f"checkpoint {path} does not match its config ({err}); {fix}") from None
    return model.eval()


def route_settings_of(sidecar: dict) -> dict | None:
    """The route rule a planner was trained with when its data was recorded traffic
    (`speed_limit_mps`, `route_accel_mps2`, derived at collection), or None (simulated data: the
    simulator's lanes carry their own limits)."""
    derived = sidecar.get("dataset", {}).get("derived") or {}
    if "speed_limit_mps" not in derived:
        return None
    return {"speed_limit_mps": float(derived["speed_limit_mps"]),
            "route_accel_mps2": float(derived["route_accel_mps2"])}
