"""The settings of a training run, light to import (the command line builds its options from
them: `riskmap.infra.cli.add_config_options`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from rasterize.config import check_predict_s
from rasterize.errors import InputError


def check_device(name: str) -> None:
    """InputError unless `name` is auto or a device torch knows (cpu, cuda, cuda:1, ...)."""
    if name in ("auto", "cpu"):
        return
    import torch

    try:
        torch.device(name)
    except (RuntimeError, ValueError):
        raise InputError(f"--device {name!r} is not a device; use auto, cpu or cuda[:N]") from None


def _normalise_kind(kind: str) -> str:
    from riskmap.planner.bc import normalise_kind

    return normalise_kind(kind)


PLANNERS = ("spatial", "spacetime")


@dataclass(frozen=True)
class TrainConfig:
    """Training run settings. Distances in metres, sigmas in metres, goal variance in cells²."""

    data: str
    out: str
    resolution: int = 50
    uncertainty_weight: float = 1.0
    sigma_x: float = 0.5
    sigma_y: float = 1.5
    goal_variance: float | None = None  # None: from the dataset's goal error, else 5.0
    goal: str = "route"
    epochs: int = 10
    batch_size: int = 32
    lr: float = 1e-4
    grad_clip: float = 10.0
    horizon: int | None = None          # value-iteration steps; default 1.6 × resolution
    gamma: float = 1.0
    val_fraction: float = 0.15          # share of episodes (or groups) held out
    val_groups: tuple[str, ...] | None = None   # recorded data: configurations held out
    val_ade_windows: int = 128          # validation windows on which the sampler runs
    augment_probability: float = 0.5    # share of training windows with a perturbed ego pose
    augment_heading_deg: float = 10.0
    augment_lateral_m: float = 1.0
    seed: int = 0
    device: str = "auto"
    backbone_weights: str | None = None
    init_checkpoint: str | None = None  # fine-tune: start from this risk-map checkpoint's weights
    max_windows: int | None = None      # cap on training windows (smoke tests)
    # Seconds of predicted future drawn in the raster (RasterConfig.predict_s); None: as the
    # dataset was collected.
    predict_s: float | None = None
    # Pixels per side of the raster the network reads, over the dataset's extent; None: as the
    # dataset was collected (200). A coarser raster trains and plans faster; 100 px still gives
    # the 50 x 50 risk-map grid 2 px a cell.
    raster_px: int | None = None
    # Reward below which the model's own risk map holds a window's goal short on the route
    # (riskmap.planner.risk_goal, the other settings its defaults); None: the route rule's goal.
    # The planner then plans with the same rule.
    risk_goal_threshold: float | None = None
    # Also learn when to be where: a head on the encoder's features predicting the arc lengths
    # of the demonstration's 12 waypoints (riskmap.planner.model.TimingHead), trained with a
    # Huber loss in metres added to the IRL loss (no weight: the head reads detached features,
    # so the two losses train disjoint parameters and Adam's steps do not see their scales);
    # the planner then times its path by it (sampler timing `learned`). `freeze_risk`: train the
    # timing head alone, the risk map kept exactly as --init-checkpoint's.
    timing_head: bool = False
    freeze_risk: bool = False
    # Which planner to train: `spatial`, the paper's (one risk map, DESIGN §3), or `spacetime`
    # (a reward map per future step and value iteration over (step, cell), DESIGN §3b): T steps
    # over the plan's 6 s, at most K cells forward and L across per step (None: from the data,
    # `riskmap.training.spacetime.reach_from_data`).
    planner: str = "spatial"
    steps: int = 12
    max_forward: int | None = None
    max_across: int | None = None
    # How samples are made; neither changes what is computed (a resume may change them):
    workers: int | None = None          # sample processes; None: 0 on the CPU, else up to 4
    cache: str = "auto"                 # sample cache folder; auto: DATA/cache, else OUT/cache; off

    def __post_init__(self) -> None:
        if self.val_groups is not None:
            object.__setattr__(self, "val_groups", tuple(self.val_groups))
        if self.predict_s is not None:
            check_predict_s(self.predict_s, "--predict-s")
        if self.raster_px is not None and not 16 <= self.raster_px <= 400:
            raise InputError(f"--raster-px must be 16 to 400 pixels a side, got {self.raster_px}")
        if self.workers is not None and self.workers < 0:
            raise InputError(f"--workers must be 0 or more, got {self.workers}")
        if not self.cache:
            raise InputError("--cache must be auto, off or a folder")
        if self.goal_variance is not None and not 0 < self.goal_variance < math.inf:
            raise InputError(f"--goal-variance must be positive (cells²), got {self.goal_variance}")
        for name in ("lr", "sigma_x", "sigma_y"):
            if not 0 < getattr(self, name) < math.inf:
                raise InputError(f"--{name.replace('_', '-')} must be a positive number, got "
                                 f"{getattr(self, name)}")
        if self.risk_goal_threshold is not None and not math.isfinite(self.risk_goal_threshold):
            raise InputError(f"--risk-goal-threshold must be a finite reward, got {self.risk_goal_threshold}")
        if self.freeze_risk and not (self.timing_head and self.init_checkpoint):
            raise InputError("--freeze-risk trains only the timing head of a trained network; pass "
                             "--timing-head and --init-checkpoint too, or drop --freeze-risk")
        if not math.isfinite(self.uncertainty_weight) or self.uncertainty_weight < 0:
            raise InputError(f"--uncertainty-weight must be a finite number >= 0, got "
                             f"{self.uncertainty_weight}")
        if self.planner not in PLANNERS:
            raise InputError(f"--planner {self.planner!r} is unknown; use {' or '.join(PLANNERS)}")
        if self.planner == "spacetime":
            clash = [name for name, on in (("--timing-head", self.timing_head),
                                           ("--freeze-risk", self.freeze_risk),
                                           ("--risk-goal-threshold", self.risk_goal_threshold is not None),
                                           ("--goal demo", self.goal != "route")) if on]
            if clash:
                raise InputError(f"--planner spacetime times its plan itself and takes the route "
                                 f"rule's goal; drop {', '.join(clash)}")
            from riskmap.planner.st_model import SpaceTimeConfig

            SpaceTimeConfig(self.steps, 1 if self.max_forward is None else self.max_forward,
                            0 if self.max_across is None else self.max_across)   # validates
        check_device(self.device)
        for name in ("epochs", "batch_size", "resolution"):
            if getattr(self, name) < 1:
                raise InputError(f"--{name.replace('_', '-')} must be positive")
        if self.horizon is None:
            object.__setattr__(self, "horizon", round(1.6 * self.resolution))
        if not 0 < self.val_fraction < 1:
            raise InputError(f"val_fraction must be in (0, 1), got {self.val_fraction}")

    def irl(self, goal_variance: float):
        """The IRL settings of this run (riskmap.planner.irl.IRLConfig) with the goal variance
        it resolved (`riskmap.training.train.resolve_goal_variance`)."""
        from dataclasses import asdict

        from riskmap.planner.irl import IRLConfig
        from riskmap.planner.risk_goal import RiskGoalConfig

        risk_goal = None
        if self.risk_goal_threshold is not None:
            risk_goal = asdict(RiskGoalConfig(threshold=self.risk_goal_threshold))
        return IRLConfig(self.horizon, self.gamma, self.uncertainty_weight, goal_variance, risk_goal)


@dataclass(frozen=True)
class BaselineTrainConfig:
    """A baseline training run. Angles in degrees, offsets in metres."""

    kind: str
    data: str
    out: str
    epochs: int = 4
    batch_size: int = 32
    lr: float = 3e-4
    history_frames: int = 4             # cnn_lstm only
    val_fraction: float = 0.15
    val_groups: tuple[str, ...] | None = None   # recorded data: configurations held out
    augment_probability: float = 0.5    # as the risk-map planner's training
    augment_heading_deg: float = 10.0
    augment_lateral_m: float = 1.0
    seed: int = 0
    max_windows: int | None = None      # cap on training windows (quick runs)
    predict_s: float | None = None      # as TrainConfig.predict_s

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", _normalise_kind(self.kind))
        if not 0 < self.lr < math.inf:
            raise InputError(f"--lr must be a positive number, got {self.lr}")
        if self.val_groups is not None:
            object.__setattr__(self, "val_groups", tuple(self.val_groups))
        if self.predict_s is not None:
            check_predict_s(self.predict_s, "--predict-s")
        for name in ("epochs", "batch_size", "history_frames"):
            if getattr(self, name) < 1:
                raise InputError(f"--{name.replace('_', '-')} must be positive")
