"""The TGAT predictor's and its training's settings, light to import (the command line builds its
options from them: `riskmap.infra.cli.add_config_options`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field


@dataclass(frozen=True)
class TGATConfig:
    hidden: int = 32
    time_dim: int = 8          # m: Φ has 2m components
    heads: int = 2
    layers: int = 2
    dropout: float = 0.1
    ds_scale_m: float = 10.0   # d_s is divided by this (and clipped to ±5) before the network
    speed_scale_mps: float = 10.0

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class GuardTrainConfig:
    epochs: int = 40
    patience: int = 8           # stop after this many epochs without a better validation AP
    lr: float = 4e-4
    batch_size: int = 8
    seed: int = 0
    model: TGATConfig = field(default_factory=TGATConfig)

    def __post_init__(self) -> None:
        import math

        from rasterize.errors import InputError

        if not (math.isfinite(self.lr) and self.lr > 0):
            raise InputError(f"--lr {self.lr}: must be a positive number")
        for name in ("epochs", "patience", "batch_size"):
            if getattr(self, name) < 1:
                raise InputError(f"--{name.replace('_', '-')} {getattr(self, name)}: must be at least 1")
