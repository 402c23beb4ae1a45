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
    from riskmap.collect import CollectConfig, collect

    config = CollectConfig(env_id=args.env, episodes=args.episodes, seed=args.seed)
    manifest = collect(config, Path(args.out), workers=args.workers, resume=args.resume,
                       progress=not args.quiet)
    counts = manifest["counts"]
    print(f"collected {counts['windows']} windows from {counts['episodes']} episodes "
          f"({counts['ego_crashes']} ego crashes) into {args.out}")
    return 0


def _cmd_figures_scenes(args: argparse.Namespace) -> int:
    from riskmap.figures import scene_figures

    paths = scene_figures(Path(args.data), Path(args.out), args.count)
    print(f"wrote {len(paths)} PNGs to {args.out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="riskmap", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("collect", help="record IDM/MOBIL demonstrations from highway-env")
    p.add_argument("--env", required=True,
                   help="highway-v0, highway-fast-v0, merge-v0, roundabout-v0 or intersection-v0")
    p.add_argument("--episodes", type=_positive_int, required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="dataset directory to create")
    p.add_argument("--workers", type=_positive_int, default=1, help="processes (default 1)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted collection")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_collect)

    p = sub.add_parser("figures", help="export PNG figures")
    fig_sub = p.add_subparsers(dest="figure", required=True)
    q = fig_sub.add_parser("scenes", help="BEV rasters with the future path overlaid")
    q.add_argument("--data", required=True, help="dataset directory (from riskmap collect)")
    q.add_argument("--out", required=True, help="directory for the PNGs")
    q.add_argument("--count", type=_positive_int, default=8)
    q.set_defaults(func=_cmd_figures_scenes)
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
