"""`adversary guard-data`: guard accident windows from CRASH attack runs
(`adversary.crash.guard_data`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def _run_guard_data(args: argparse.Namespace) -> int:
    from adversary.crash.guard_data import GuardDataConfig, export

    config = GuardDataConfig(split=args.split, val_fraction=args.val_fraction, cut=args.cut)
    summary = export([Path(d) for d in args.attacks], Path(args.out), config, resume=args.resume,
                     progress=not args.quiet)
    for split, c in summary["splits"].items():
        print(f"{split}: {c['windows']} windows ({c['positives']} positive) from {c['episodes']} attack "
              f"records ({c['crashes']} crashes)")
    print(f"{summary['partner_is_adversary']}/{sum(c['crashes'] for c in summary['splits'].values())} crashes: "
          f"positives name the adversary; skipped {summary['skipped']}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("guard-data", help="guard accident windows from attack runs (positives from "
                                                 "the adversary's collisions)")
    p.add_argument("--attacks", action="append", required=True,
                   help="an `adversary attack --out` directory (repeat for several)")
    p.add_argument("--out", required=True, help="guard dataset directory (may already hold natural windows)")
    p.add_argument("--split", default="adversarial",
                   help="split of the windows, e.g. adversarial (held-out test) or train")
    p.add_argument("--val-fraction", type=float, default=0.0,
                   help="the last share of each run's scenes goes to the val split")
    p.add_argument("--cut", default="contact", choices=("contact", "judge"),
                   help="cut a collision at the onset of the box contact (as highway-env ends natural "
                        "episodes) or at the judged step (IoU > 0.02)")
    p.add_argument("--resume", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=_run_guard_data)
