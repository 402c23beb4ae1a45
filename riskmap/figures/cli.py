"""`riskmap figures scenes|plans`: PNG figures of the data and of the planner."""

from __future__ import annotations

import argparse
from pathlib import Path

from riskmap.infra.cli import add_command_group, comma_list, positive_float, positive_int


def _cmd_figures_scenes(args: argparse.Namespace) -> int:
    from riskmap.figures.panels import scene_figures

    paths = scene_figures(Path(args.data), Path(args.out), args.count)
    print(f"wrote {len(paths)} PNGs to {args.out}")
    return 0


def _cmd_figures_plans(args: argparse.Namespace) -> int:
    from riskmap.figures.panels import plan_figures

    paths = plan_figures(Path(args.checkpoint), Path(args.data), Path(args.out), args.count,
                         args.seed, groups=args.groups, goal=args.goal, goal_variance=args.goal_variance)
    print(f"wrote {len(paths)} PNGs to {args.out}")
    return 0


def add_parsers(sub) -> None:
    fig_sub = add_command_group(sub, "figures", help="export PNG figures", dest="figure")
    q = fig_sub.add_parser("scenes", help="BEV rasters with the future path overlaid")
    q.add_argument("--data", required=True, help="dataset directory (from riskmap collect)")
    q.add_argument("--out", required=True, help="directory for the PNGs")
    q.add_argument("--count", type=positive_int, default=8,
                   help="windows drawn, spread evenly over the dataset (one PNG each)")
    q.set_defaults(func=_cmd_figures_scenes)
    q = fig_sub.add_parser("plans", help="BEV | risk map | goal map | SVF | plan vs demo panels")
    q.add_argument("--checkpoint", required=True, help="risk-map planner checkpoint")
    q.add_argument("--data", required=True, help="dataset directory (same raster config)")
    q.add_argument("--out", required=True, help="directory for the PNGs")
    q.add_argument("--count", type=positive_int, default=6,
                   help="windows planned, spread evenly over the dataset (or --groups)")
    q.add_argument("--seed", type=int, default=0, help="the planner's seed")
    q.add_argument("--groups", type=comma_list, default=None,
                   help="recorded data: only windows of these configurations (names or numbers)")
    q.add_argument("--goal", choices=("route", "human"), default="route",
                   help="plan towards the route rule's goal or the human's end (as evaluate --goal)")
    q.add_argument("--goal-variance", type=positive_float, default=None,
                   help="cells²; planning-time goal variance (default: the checkpoint's)")
    q.set_defaults(func=_cmd_figures_plans)
