"""`adversary guard-data`: guard accident windows from CRASH attack runs and search runs.

The command sits above both (`adversary.crash.guard_data`, `adversary.search.guard_data`) and
writes their windows into one guard dataset directory, next to `riskmap guard collect`'s.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from riskmap.infra.cli import add_run_options


def _run_guard_data(args: argparse.Namespace) -> int:
    from adversary.crash.guard_data import GuardDataConfig, export
    from adversary.search.guard_data import export_search
    from rasterize.errors import InputError
    from riskmap.guard.dataset import split_counts

    if not args.attacks and not args.search:
        raise InputError("adversary guard-data needs --attacks DIR (an `adversary attack --out`) or "
                         "--search DIR (an `adversary search --out`), or both")
    config = GuardDataConfig(split=args.split, val_fraction=args.val_fraction, cut=args.cut,
                             skip_scenes=args.skip_scenes)
    if args.attacks:
        summary = export([Path(d) for d in args.attacks], Path(args.out), config, resume=args.resume,
                         progress=not args.quiet)
        _print_split_counts(summary["splits"], "attack records")
        print(f"{summary['partner_is_adversary']}/{sum(c['crashes'] for c in summary['splits'].values())} "
              f"crashes: positives name the adversary; skipped {summary['skipped']}")
    if args.search:
        metas = export_search([Path(d) for d in args.search], Path(args.out), config.split, config.val_fraction,
                              config.windows, resume=args.resume, progress=not args.quiet)
        _print_split_counts(split_counts(metas), "searched scenarios")
    return 0


def _print_split_counts(splits: dict, episodes_are: str) -> None:
    """One line per split of what it now holds; `episodes_are` names what an episode was made from."""
    for split, c in splits.items():
        print(f"{split}: {c['windows']} windows ({c['positives']} positive) from {c['episodes']} "
              f"{episodes_are} ({c['crashes']} crashes)")


def add_parsers(subparsers) -> None:
    p = subparsers.add_parser("guard-data", help="guard accident windows from attack and search runs "
                                                 "(positives from the adversary's collisions)")
    p.add_argument("--attacks", action="append", default=[],
                   help="an `adversary attack --out` directory (repeat for several)")
    p.add_argument("--search", action="append", default=[],
                   help="an `adversary search --out` directory: its evaluated scenarios, driven again "
                        "(repeat for several)")
    p.add_argument("--out", required=True, help="guard dataset directory (may already hold natural windows)")
    p.add_argument("--split", default="adversarial",
                   help="split of the windows, e.g. adversarial (held-out test) or train")
    p.add_argument("--val-fraction", type=float, default=0.0,
                   help="the last share of each run's scenes goes to the val split")
    p.add_argument("--skip-scenes", type=int, default=0,
                   help="leave out the first N scenes of every run (kept unseen for a closed-loop evaluation)")
    p.add_argument("--cut", default="contact", choices=("contact", "judge"),
                   help="cut a collision at the onset of the box contact (as highway-env ends natural "
                        "episodes) or at the judged step (IoU > 0.02)")
    add_run_options(p, _run_guard_data,
                    resume="continue an interrupted export into --out (windows already written are kept)")
