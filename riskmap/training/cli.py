"""`riskmap train` (the risk-aware planner) and `riskmap train-baseline` (Table I baselines)."""

from __future__ import annotations

import argparse
from pathlib import Path

from riskmap.infra.cli import positive_int


def _cmd_train(args: argparse.Namespace) -> int:
    from riskmap.training.train import TrainConfig, train

    config = TrainConfig(
        data=args.data, out=args.out, resolution=args.resolution,
        uncertainty_weight=args.uncertainty_weight, sigma_x=args.sigma_x, sigma_y=args.sigma_y,
        goal_variance=args.goal_variance, goal=args.goal, epochs=args.epochs,
        batch_size=args.batch_size, lr=args.lr, horizon=args.horizon, seed=args.seed,
        device=args.device, backbone_weights=args.backbone_weights, max_windows=args.max_windows,
    )
    best = train(config, resume=args.resume, progress=not args.quiet)
    print(f"best epoch {best.get('epoch')}: val ADE {best['val_ade_m']:.2f} m; "
          f"checkpoint {Path(args.out) / 'best.safetensors'}")
    return 0


def _cmd_train_baseline(args: argparse.Namespace) -> int:
    from riskmap.training.train_baseline import BaselineTrainConfig, train_baseline

    config = BaselineTrainConfig(kind=args.kind, data=args.data, out=args.out, epochs=args.epochs,
                                 batch_size=args.batch_size, lr=args.lr,
                                 history_frames=args.history_frames, seed=args.seed,
                                 max_windows=args.max_windows)
    best = train_baseline(config, resume=args.resume, progress=not args.quiet)
    print(f"best epoch {best.get('epoch')}: val ADE {best['val_ade_m']:.2f} m; "
          f"checkpoint {Path(args.out) / 'best.safetensors'}")
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser("train", help="train the risk-map planner (MaxEnt IRL)")
    p.add_argument("--data", required=True, help="dataset directory (from riskmap collect)")
    p.add_argument("--out", required=True, help="run directory")
    p.add_argument("--resolution", type=positive_int, default=50, help="risk-map cells a side")
    p.add_argument("--uncertainty-weight", type=float, default=1.0, help="v of eq. 5")
    p.add_argument("--sigma-x", type=float, default=0.5, help="uncertainty across agents (m)")
    p.add_argument("--sigma-y", type=float, default=1.5, help="uncertainty along agents (m)")
    p.add_argument("--goal-variance", type=float, default=5.0, help="goal Gaussian (cells^2)")
    p.add_argument("--goal", choices=("route", "demo"), default="route",
                   help="goal of each window: the route rule (as in closed loop) or the demo's end")
    p.add_argument("--epochs", type=positive_int, default=10)
    p.add_argument("--batch-size", type=positive_int, default=32)
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--horizon", type=positive_int, default=None,
                   help="value-iteration steps (default 1.6 x resolution)")
    p.add_argument("--device", default="auto", help="auto, cpu or cuda[:N]")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--backbone-weights", default=None,
                   help="local torchvision ResNet-34 state dict to initialise the stem")
    p.add_argument("--max-windows", type=positive_int, default=None,
                   help="use at most this many training windows (quick runs)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run exactly")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_train)

    p = sub.add_parser("train-baseline", help="train a behaviour-cloning baseline (cnn, cnn_lstm, rvsg)")
    p.add_argument("kind", choices=("cnn", "cnn_lstm", "cnn-lstm", "rvsg"))
    p.add_argument("--data", required=True, help="dataset directory (from riskmap collect)")
    p.add_argument("--out", required=True, help="run directory")
    p.add_argument("--epochs", type=positive_int, default=4)
    p.add_argument("--batch-size", type=positive_int, default=32)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--history-frames", type=positive_int, default=4,
                   help="cnn_lstm: raster frames 0.5 s apart fed to the LSTM")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-windows", type=positive_int, default=None,
                   help="use at most this many training windows (quick runs)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run exactly")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_train_baseline)
