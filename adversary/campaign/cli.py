"""The `adversary stress-test` subcommand."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parsers(subparsers) -> None:
    p = subparsers.add_parser("stress-test", help="run a stress-test campaign into a result store",
                              description="Run every (planner, scene, attack) job of a campaign "
                                          "config; results stream into DIR, resumable.")
    p.add_argument("--config", required=True, help="campaign YAML (see experiments/campaigns/)")
    p.add_argument("--out", required=True, help="campaign directory (result store)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="local process pool, or Ray tasks (pip install 'riskmap-toolkit[ray]')")
    p.add_argument("--workers", type=int, default=1, help="parallel jobs (processes or Ray CPUs)")
    p.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    p.add_argument("--resume", action="store_true", help="continue a campaign in --out")
    p.add_argument("--max-jobs", type=int, default=None,
                   help="stop after this many new jobs (split a campaign over several sittings)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from adversary.campaign.config import load_campaign
    from adversary.campaign.run import RunOptions, run_campaign
    from rasterize.errors import InputError

    if args.workers < 1:
        raise InputError(f"--workers {args.workers}: must be at least 1")
    if args.max_jobs is not None and args.max_jobs < 1:
        raise InputError(f"--max-jobs {args.max_jobs}: must be at least 1")
    config = load_campaign(Path(args.config))
    counts = run_campaign(config, Path(args.out),
                          RunOptions(args.backend, args.workers, args.address, args.resume,
                                     args.max_jobs, not args.quiet),
                          Path(args.config).read_text())
    print(f"{counts['finished']}/{counts['total']} jobs finished ({counts['ran']} now, "
          f"{counts['failed']} failed, {counts['collided']} collisions) in {args.out}")
    return 0
