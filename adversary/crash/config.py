"""Training settings of CRASH's models, light to import (the command line builds its options from
them: `riskmap.infra.cli.add_config_options`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from rasterize.errors import InputError


def _check(ok: bool, flag: str, value, rule: str) -> None:
    if not ok:
        raise InputError(f"{flag} {value}: must be {rule}")


@dataclass(frozen=True)
class TrainTrafficConfig:
    epochs: int = 30
    batch_size: int = 32
    lr: float = 1e-3
    kl_weight: float = 0.05         # beta
    free_bits: float = 2.0          # nats per agent the KL may use without penalty; without it the
                                    # posterior collapses onto the prior (highway futures are very
                                    # predictable from the past) and the decoder ignores z, which
                                    # leaves the attack nothing to optimise
    val_fraction: float = 0.15      # share of each dataset's episodes held out
    seed: int = 0
    max_windows_per_episode: int = 0   # 0: all

    def __post_init__(self) -> None:
        _check(math.isfinite(self.lr) and self.lr > 0, "--lr", self.lr, "a positive number")
        _check(math.isfinite(self.kl_weight) and self.kl_weight >= 0, "--kl-weight", self.kl_weight,
               "a finite number >= 0")
        _check(math.isfinite(self.free_bits) and self.free_bits >= 0, "--free-bits", self.free_bits,
               "a finite number of nats >= 0")
        _check(self.max_windows_per_episode >= 0, "--max-windows-per-episode",
               self.max_windows_per_episode, "0 (all) or more")
        _check(0 <= self.val_fraction < 1, "val_fraction", self.val_fraction, "in [0, 1)")


@dataclass(frozen=True)
class TrainSelectorConfig:
    label_iterations: int = 60      # short generation per candidate
    max_scenes: int = 250
    windows_per_episode: int = 4
    epochs: int = 300
    lr: float = 1e-3
    val_fraction: float = 0.2       # of the labelled scenes (by order, i.e. by episode)
    seed: int = 0

    def __post_init__(self) -> None:
        _check(math.isfinite(self.lr) and self.lr > 0, "--lr", self.lr, "a positive number")
        _check(0 <= self.val_fraction < 1, "val_fraction", self.val_fraction, "in [0, 1)")
