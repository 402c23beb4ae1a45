"""`riskmap train` (the risk-aware planner) and `riskmap train-baseline` (Table I baselines)."""

from __future__ import annotations

import argparse
from pathlib import Path

from riskmap.infra.cli import add_config_options, add_run_options, config_from_args, positive_int
from riskmap.training.config import PLANNERS, BaselineTrainConfig, TrainConfig


def _cmd_train(args: argparse.Namespace) -> int:
    from riskmap.training.train import train

    best = train(config_from_args(TrainConfig, args), resume=args.resume, progress=not args.quiet)
    print(f"best epoch {best.get('epoch')}: val ADE {best['val_ade_m']:.2f} m; "
          f"checkpoint {Path(args.out) / 'best.safetensors'}")
    return 0


def _cmd_train_baseline(args: argparse.Namespace) -> int:
    from riskmap.training.train_baseline import train_baseline

    best = train_baseline(config_from_args(BaselineTrainConfig, args), resume=args.resume,
                          progress=not args.quiet)
    print(f"best epoch {best.get('epoch')}: val ADE {best['val_ade_m']:.2f} m; "
          f"checkpoint {Path(args.out) / 'best.safetensors'}")
    return 0


POSITIVE = {name: positive_int for name in ("resolution", "epochs", "batch_size", "horizon",
                                             "max_windows", "history_frames", "steps")}
HELP = {
    "data": "dataset directory (from riskmap collect)",
    "out": "run directory",
    "resolution": "risk-map cells a side",
    "epochs": "passes over the training windows",
    "batch_size": "windows per optimiser step",
    "lr": "Adam's learning rate",
    "seed": "seeds the weights' initialisation, the augmentation and the order of the windows",
    "uncertainty_weight": "v of eq. 5",
    "sigma_x": "uncertainty across agents (m)",
    "sigma_y": "uncertainty along agents (m)",
    "goal_variance": "goal Gaussian (cells^2); default: from a recorded dataset's goal error, else 5",
    "val_groups": "recorded data: configurations to validate on (names or numbers, comma-separated); "
                  "default: the last val-fraction of them",
    "init_checkpoint": "fine-tune: start from this risk-map checkpoint's weights",
    "goal": "goal of each window: the route rule (as in closed loop) or the demo's end",
    "horizon": "value-iteration steps (default 1.6 x resolution)",
    "device": "auto, cpu or cuda[:N]",
    "backbone_weights": "local torchvision ResNet-34 state dict to initialise the stem",
    "max_windows": "use at most this many training windows (quick runs)",
    "history_frames": "cnn_lstm: raster frames 0.5 s apart fed to the LSTM",
    "workers": "processes building samples while the network trains (same batches); default: "
               "0 on the CPU, where the network's threads use every core, else up to 4",
    "cache": "sample cache folder: auto (DATA/cache, else OUT/cache), off, or a folder; "
             "holds each window as recorded once built (about 0.4 MB a window)",
    "risk_goal_threshold": "hold each window's goal short on the route where the model's own risk map falls "
                           "below this reward, as the planner then does in closed loop "
                           "(riskmap.planner.risk_goal; default: the route rule's goal)",
    "timing_head": "also learn the demonstrations' timing: a head predicting how far along its path "
                   "the ego is at each waypoint time, by which the planner then times its plan",
    "freeze_risk": "train only the timing head; the risk map stays --init-checkpoint's",
    "planner": "spatial: the paper's planner (one risk map); spacetime: a reward map per future "
               "step and value iteration over (step, cell), so it can wait and yield (DESIGN 3b); "
               "default: spatial",
    "steps": "spacetime: reward maps over the 6 s plan (12, the default: one per 0.5 s; 6, 4 or "
             "3: coarser)",
    "max_forward": "spacetime: cells the ego may move forward per step (K); default: from the "
                   "demonstrations' fastest steps",
    "max_across": "spacetime: cells the ego may move sideways per step (L); default: from the "
                  "demonstrations",
    "raster_px": "pixels per side of the raster the network reads, over the dataset's extent "
                 "(default: as collected, 200); the planner then draws the same",
    "predict_s": "draw the other agents' predicted future (constant speed along their lanes) and "
                 "the traffic lights' red over this many seconds as 2 extra raster channels "
                 "(0: none; default: as the dataset was collected, normally none)",
}


def add_parsers(sub) -> None:
    p = sub.add_parser("train", help="train the risk-map planner (MaxEnt IRL)")
    add_config_options(p, TrainConfig, "data", "out", "resolution", "uncertainty_weight", "sigma_x",
                       "sigma_y", "goal_variance", "goal", "epochs", "batch_size", "lr", "horizon",
                       "val_groups", "device", "seed", "backbone_weights", "init_checkpoint",
                       "max_windows", "predict_s", "raster_px", "risk_goal_threshold", "timing_head",
                       "freeze_risk", "planner", "steps", "max_forward", "max_across", "workers", "cache", help=HELP,
                       option_types=POSITIVE, choices={"planner": PLANNERS})
    add_run_options(p, _cmd_train, resume="continue an interrupted run exactly")

    p = sub.add_parser("train-baseline", help="train a behaviour-cloning baseline (cnn, cnn_lstm, rvsg)")
    p.add_argument("kind", choices=("cnn", "cnn_lstm", "cnn-lstm", "rvsg"),
                   help="the baseline network (cnn-lstm is another spelling of cnn_lstm)")
    add_config_options(p, BaselineTrainConfig, "data", "out", "epochs", "batch_size", "lr",
                       "history_frames", "val_groups", "seed", "max_windows", "predict_s",
                       help=HELP, option_types=POSITIVE)
    add_run_options(p, _cmd_train_baseline, resume="continue an interrupted run exactly")
