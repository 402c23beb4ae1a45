"""`riskmap collect`: demonstrations from highway-env or recorded CommonRoad traffic."""

from __future__ import annotations

import argparse
from pathlib import Path

from rasterize.errors import InputError
from riskmap.infra.cli import add_run_options, positive_int


def _cmd_collect(args: argparse.Namespace) -> int:
    if args.from_commonroad:
        if args.env is not None or args.episodes is not None:
            raise InputError("pass either --from-commonroad FILES or --env ENV --episodes N, not both")
        return _cmd_collect_commonroad(args)
    if args.env is None or args.episodes is None:
        raise InputError("collect needs --env ENV and --episodes N (or --from-commonroad FILES)")
    from riskmap.data.collect import CollectConfig, collect

    config = CollectConfig(env_id=args.env, episodes=args.episodes, seed=args.seed, human=args.human)
    manifest = collect(config, Path(args.out), workers=args.workers, resume=args.resume,
                       progress=not args.quiet)
    counts = manifest["counts"]
    print(f"collected {counts['windows']} windows from {counts['episodes']} episodes "
          f"({counts['ego_crashes']} ego crashes) into {args.out}")
    return 0


def _cmd_collect_commonroad(args: argparse.Namespace) -> int:
    from riskmap.data.collect_commonroad import collect_commonroad

    manifest = collect_commonroad(args.from_commonroad, Path(args.out), resume=args.resume,
                                  progress=not args.quiet, seed=args.seed)
    counts = manifest["counts"]
    print(f"collected {counts['windows']} windows of {counts['episodes']} recorded demonstrators "
          f"into {args.out}")
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser("collect", help="record IDM/MOBIL demonstrations from highway-env, or cut "
                                       "them from recorded CommonRoad traffic")
    p.add_argument("--env",
                   help="highway-v0, highway-fast-v0, merge-v0, roundabout-v0 or intersection-v0")
    p.add_argument("--episodes", type=positive_int, help="episodes to record (with --env)")
    p.add_argument("--from-commonroad", nargs="+", metavar="DIR_OR_FILE",
                   help="CommonRoad .xml files or directories: every recorded vehicle with 2 s of "
                        "history and 6 s of future is a demonstrator (instead of --env)")
    p.add_argument("--human", choices=("idm", "yielding"),
                   help="the demonstrator: idm (IDM/MOBIL) or yielding (IDM/MOBIL that gives way "
                        "at conflict zones by gap acceptance); default: yielding at "
                        "intersection-v0, idm elsewhere")
    p.add_argument("--seed", type=int, default=0,
                   help="episode i resets the env with a seed drawn from (SEED, i); with "
                        "--from-commonroad only recorded in the manifest")
    p.add_argument("--out", required=True, help="dataset directory to create")
    p.add_argument("--workers", type=positive_int, default=1, help="processes (default 1)")
    add_run_options(p, _cmd_collect, resume="continue an interrupted collection", quiet="no progress bar")
