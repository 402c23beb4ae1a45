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
    position_scale_m: float = 20.0   # relative positions are divided by this (clipped to ±5)
    speed_scale_mps: float = 10.0    # speeds and relative velocities are divided by this
    horizon_s: float = 2.0     # the target event this long after the last observed one (features.HORIZONS_S)
    closest_approach: bool = False   # add each event's constant-velocity closest approach (distance, time)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class GuardTrainConfig:
    epochs: int = 40
    patience: int = 8           # stop after this many epochs without a better validation AP
    lr: float = 4e-4
    batch_size: int = 8
    seed: int = 0
    ttc_weight: float = 0.5     # the time-to-contact loss (smooth L1, s, positives only) beside the BCE
    alert_ratio: float = 0.05   # the alert threshold is set so that this share of the validation
                                # decision frames alerts (`riskmap.guard.threshold`)
    model: TGATConfig = field(default_factory=TGATConfig)

    def __post_init__(self) -> None:
        import math

        from rasterize.errors import InputError

        if not (math.isfinite(self.lr) and self.lr > 0):
            raise InputError(f"--lr {self.lr}: must be a positive number")
        from riskmap.guard.features import MAX_HORIZON_S

        for name in ("epochs", "patience", "batch_size"):
            if getattr(self, name) < 1:
                raise InputError(f"--{name.replace('_', '-')} {getattr(self, name)}: must be at least 1")
        if not (math.isfinite(self.ttc_weight) and self.ttc_weight >= 0):
            raise InputError(f"--ttc-weight {self.ttc_weight}: must be a number ≥ 0")
        if not 0 < self.alert_ratio < 1:
            raise InputError(f"--alert-ratio {self.alert_ratio}: must be a share in (0, 1), e.g. 0.05")
        if not 0 < self.model.horizon_s <= MAX_HORIZON_S:
            raise InputError(f"--horizon-s {self.model.horizon_s}: must be in (0, {MAX_HORIZON_S:g}] s")
