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
    # The realism term (STRIVE's prior losses; adversary/crash/train_traffic.py, `realism_loss`):
    # each batch one reparameterised sample of the PRIOR is decoded per scene and penalised with
    #   prior_collision_weight x disc overlap (m) of every pair of real agents, summed over the
    #                            12 future steps and the pairs, per real agent of the batch; pairs
    #                            whose logged futures already overlap (the data's own crashes) are
    #                            left out
    #   prior_off_road_weight  x distance (m) of the box corners to the drivable area, summed
    #                            over the 4 corners and 12 steps, per real agent; agents whose
    #                            logged future leaves the drivable area or stops early are left out
    # Both per unit of the reconstruction loss; 0 and 0: no prior sample (the old training).
    prior_collision_weight: float = 0.0
    prior_off_road_weight: float = 0.0

    def __post_init__(self) -> None:
        _check(math.isfinite(self.lr) and self.lr > 0, "--lr", self.lr, "a positive number")
        _check(math.isfinite(self.prior_collision_weight) and self.prior_collision_weight >= 0,
               "--prior-collision-weight", self.prior_collision_weight, "a finite number >= 0")
        _check(math.isfinite(self.prior_off_road_weight) and self.prior_off_road_weight >= 0,
               "--prior-off-road-weight", self.prior_off_road_weight, "a finite number >= 0")
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
    # What the selector minimises (adversary/crash/train_selector.py): "labels", the standardised
    # final losses of a short attack by every candidate; "unrolled", the generation loss after
    # `unroll_steps` differentiable gradient steps of size `unroll_lr` on the latents, with p in
    # the loss (adversary/crash/unrolled.py). With "unrolled" only the held-out scenes are labelled.
    objective: str = "labels"
    unroll_steps: int = 5
    unroll_lr: float = 0.25         # eta; plain gradient descent on z diverges from about 0.5

    def __post_init__(self) -> None:
        _check(math.isfinite(self.lr) and self.lr > 0, "--lr", self.lr, "a positive number")
        _check(0 <= self.val_fraction < 1, "val_fraction", self.val_fraction, "in [0, 1)")
        _check(self.objective in SELECTOR_OBJECTIVES, "--objective", self.objective,
               " or ".join(SELECTOR_OBJECTIVES))
        _check(self.unroll_steps >= 1, "--unroll-steps", self.unroll_steps, "1 or more")
        _check(math.isfinite(self.unroll_lr) and self.unroll_lr > 0, "--unroll-lr", self.unroll_lr,
               "a positive number")


SELECTOR_OBJECTIVES = ("labels", "unrolled")
