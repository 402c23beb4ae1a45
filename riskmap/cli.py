"""The `riskmap` command line: collect demonstrations, export figures (more as the toolkit grows)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rasterize.errors import InputError


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} must be at least 1")
    return value


def _cmd_collect(args: argparse.Namespace) -> int:
    if args.from_commonroad:
        if args.env is not None or args.episodes is not None:
            raise InputError("pass either --from-commonroad FILES or --env ENV --episodes N, not both")
        return _cmd_collect_commonroad(args)
    if args.env is None or args.episodes is None:
        raise InputError("collect needs --env ENV and --episodes N (or --from-commonroad FILES)")
    from riskmap.collect import CollectConfig, collect

    config = CollectConfig(env_id=args.env, episodes=args.episodes, seed=args.seed)
    manifest = collect(config, Path(args.out), workers=args.workers, resume=args.resume,
                       progress=not args.quiet)
    counts = manifest["counts"]
    print(f"collected {counts['windows']} windows from {counts['episodes']} episodes "
          f"({counts['ego_crashes']} ego crashes) into {args.out}")
    return 0


def _cmd_collect_commonroad(args: argparse.Namespace) -> int:
    from riskmap.collect_commonroad import collect_commonroad

    manifest = collect_commonroad(args.from_commonroad, Path(args.out), resume=args.resume,
                                  progress=not args.quiet, seed=args.seed)
    counts = manifest["counts"]
    print(f"collected {counts['windows']} windows of {counts['episodes']} recorded demonstrators "
          f"into {args.out}")
    return 0


def _cmd_figures_scenes(args: argparse.Namespace) -> int:
    from riskmap.figures import scene_figures

    paths = scene_figures(Path(args.data), Path(args.out), args.count)
    print(f"wrote {len(paths)} PNGs to {args.out}")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    from riskmap.train import TrainConfig, train

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


def _cmd_drive(args: argparse.Namespace) -> int:
    from riskmap.drive import DriveConfig, drive

    if bool(args.checkpoint) == bool(args.planner):
        raise InputError("pass exactly one of --checkpoint CKPT or --planner SPEC")
    spec = args.planner or f"riskmap:{args.checkpoint}"
    config = DriveConfig(env_id=args.env, episodes=args.episodes, seed=args.seed)
    summary = drive(config, spec, Path(args.out), resume=args.resume, frames=args.frames,
                    progress=not args.quiet, goal_variance=args.goal_variance)["summary"]
    print(f"{spec} on {args.env}: {summary['episodes']} episodes, collision rate "
          f"{summary['collision_rate']:.2f}, distance {summary['distance_m']:.0f} m, "
          f"min gap {summary['min_gap_m']:.1f} m -> {Path(args.out) / 'summary.json'}")
    return 0


def _cmd_train_baseline(args: argparse.Namespace) -> int:
    from riskmap.train_baseline import BaselineTrainConfig, train_baseline

    config = BaselineTrainConfig(kind=args.kind, data=args.data, out=args.out, epochs=args.epochs,
                                 batch_size=args.batch_size, lr=args.lr,
                                 history_frames=args.history_frames, seed=args.seed,
                                 max_windows=args.max_windows)
    best = train_baseline(config, resume=args.resume, progress=not args.quiet)
    print(f"best epoch {best.get('epoch')}: val ADE {best['val_ade_m']:.2f} m; "
          f"checkpoint {Path(args.out) / 'best.safetensors'}")
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from riskmap.evaluate import EvalConfig, evaluate

    planners = tuple(p.strip() for p in args.planners.split(",") if p.strip())
    if args.commonroad:
        from riskmap.evaluate_commonroad import evaluate_commonroad

        if args.mode != "log" or args.env or args.episodes:
            raise InputError("--commonroad evaluates recorded vehicles in log mode: drop --env, "
                             "--episodes and --mode reactive")
        evaluate_commonroad(args.commonroad, planners, Path(args.out), seed=args.seed,
                            resume=args.resume, progress=not args.quiet)
        print((Path(args.out) / "table.md").read_text(), end="")
        return 0
    if not args.env or not args.episodes:
        raise InputError("evaluate needs --env ENV and --episodes N (or --commonroad FILES)")
    config = EvalConfig(env_id=args.env, planners=planners, episodes=args.episodes, seed=args.seed,
                        mode=args.mode, episode_s=args.episode_s)
    evaluate(config, Path(args.out), workers=args.workers, resume=args.resume,
             progress=not args.quiet)
    print((Path(args.out) / "table.md").read_text(), end="")
    return 0


def _cmd_figures_plans(args: argparse.Namespace) -> int:
    from riskmap.figures import plan_figures

    paths = plan_figures(Path(args.checkpoint), Path(args.data), Path(args.out), args.count,
                         args.seed)
    print(f"wrote {len(paths)} PNGs to {args.out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="riskmap", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("collect", help="record IDM/MOBIL demonstrations from highway-env, or cut "
                                       "them from recorded CommonRoad traffic")
    p.add_argument("--env",
                   help="highway-v0, highway-fast-v0, merge-v0, roundabout-v0 or intersection-v0")
    p.add_argument("--episodes", type=_positive_int)
    p.add_argument("--from-commonroad", nargs="+", metavar="DIR_OR_FILE",
                   help="CommonRoad .xml files or directories: every recorded vehicle with 2 s of "
                        "history and 6 s of future is a demonstrator (instead of --env)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="dataset directory to create")
    p.add_argument("--workers", type=_positive_int, default=1, help="processes (default 1)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted collection")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_collect)

    p = sub.add_parser("train", help="train the risk-map planner (MaxEnt IRL)")
    p.add_argument("--data", required=True, help="dataset directory (from riskmap collect)")
    p.add_argument("--out", required=True, help="run directory")
    p.add_argument("--resolution", type=_positive_int, default=50, help="risk-map cells a side")
    p.add_argument("--uncertainty-weight", type=float, default=1.0, help="v of eq. 5")
    p.add_argument("--sigma-x", type=float, default=0.5, help="uncertainty across agents (m)")
    p.add_argument("--sigma-y", type=float, default=1.5, help="uncertainty along agents (m)")
    p.add_argument("--goal-variance", type=float, default=5.0, help="goal Gaussian (cells^2)")
    p.add_argument("--goal", choices=("route", "demo"), default="route",
                   help="goal of each window: the route rule (as in closed loop) or the demo's end")
    p.add_argument("--epochs", type=_positive_int, default=10)
    p.add_argument("--batch-size", type=_positive_int, default=32)
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--horizon", type=_positive_int, default=None,
                   help="value-iteration steps (default 1.6 x resolution)")
    p.add_argument("--device", default="auto", help="auto, cpu or cuda[:N]")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--backbone-weights", default=None,
                   help="local torchvision ResNet-34 state dict to initialise the stem")
    p.add_argument("--max-windows", type=_positive_int, default=None,
                   help="use at most this many training windows (quick runs)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run exactly")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_train)

    p = sub.add_parser("train-baseline", help="train a behaviour-cloning baseline (cnn, cnn_lstm, rvsg)")
    p.add_argument("kind", choices=("cnn", "cnn_lstm", "cnn-lstm", "rvsg"))
    p.add_argument("--data", required=True, help="dataset directory (from riskmap collect)")
    p.add_argument("--out", required=True, help="run directory")
    p.add_argument("--epochs", type=_positive_int, default=4)
    p.add_argument("--batch-size", type=_positive_int, default=32)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--history-frames", type=_positive_int, default=4,
                   help="cnn_lstm: raster frames 0.5 s apart fed to the LSTM")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-windows", type=_positive_int, default=None,
                   help="use at most this many training windows (quick runs)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run exactly")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_train_baseline)

    p = sub.add_parser("drive", help="drive closed-loop episodes with a planner")
    p.add_argument("--checkpoint", help="risk-map planner checkpoint (same as --planner riskmap:CKPT)")
    p.add_argument("--planner", help="planner SPEC: idm, cv or riskmap:PATH")
    p.add_argument("--env", required=True)
    p.add_argument("--episodes", type=_positive_int, required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True)
    p.add_argument("--frames", action="store_true", help="write a PNG per replan")
    p.add_argument("--goal-variance", type=float, default=None,
                   help="cells²; planning-time goal variance of a risk-map planner (default: the "
                        "checkpoint's)")
    p.add_argument("--resume", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_drive)

    p = sub.add_parser("evaluate", help="closed-loop benchmark of planners (Table I metrics)")
    p.add_argument("--planners", required=True,
                   help="comma-separated planner SPECs: idm, replay, cv, riskmap:PATH, cnn:PATH, "
                        "cnn_lstm:PATH, rvsg:PATH")
    p.add_argument("--env", help="highway-env id (simulated scenes)")
    p.add_argument("--episodes", type=_positive_int, help="episodes (simulated scenes)")
    p.add_argument("--commonroad", nargs="+", metavar="DIR_OR_FILE",
                   help="evaluate on recorded vehicles of CommonRoad files instead (log mode)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--mode", choices=("log", "reactive"), default="log",
                   help="log: other vehicles replay the human's record; reactive: IDM/MOBIL traffic")
    p.add_argument("--episode-s", type=float, default=None,
                   help="simulated seconds per episode (default: the family's length)")
    p.add_argument("--out", required=True)
    p.add_argument("--workers", type=_positive_int, default=1, help="processes (default 1)")
    p.add_argument("--resume", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser("figures", help="export PNG figures")
    fig_sub = p.add_subparsers(dest="figure", required=True)
    q = fig_sub.add_parser("scenes", help="BEV rasters with the future path overlaid")
    q.add_argument("--data", required=True, help="dataset directory (from riskmap collect)")
    q.add_argument("--out", required=True, help="directory for the PNGs")
    q.add_argument("--count", type=_positive_int, default=8)
    q.set_defaults(func=_cmd_figures_scenes)
    q = fig_sub.add_parser("plans", help="BEV | risk map | goal map | SVF | plan vs demo panels")
    q.add_argument("--checkpoint", required=True, help="risk-map planner checkpoint")
    q.add_argument("--data", required=True, help="dataset directory (same raster config)")
    q.add_argument("--out", required=True, help="directory for the PNGs")
    q.add_argument("--count", type=_positive_int, default=6)
    q.add_argument("--seed", type=int, default=0)
    q.set_defaults(func=_cmd_figures_plans)

    from riskmap.guard.cli import add_parser as add_guard_parser

    add_guard_parser(sub, _positive_int)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as err:
        print(f"riskmap: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("riskmap: interrupted; finished work is kept, rerun with --resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
