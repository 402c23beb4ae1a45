"""The `adversary report` subcommand."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parsers(subparsers) -> None:
    p = subparsers.add_parser("report", help="HTML report of a stress-test campaign",
                              description="Write report.html, report.json and figures/ for a "
                                          "campaign directory.")
    p.add_argument("dir", help="campaign directory written by `adversary stress-test --out`")
    p.add_argument("--out", default=None, help="where to write the report (default: DIR)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from adversary.report.page import make_report

    report = make_report(Path(args.dir), Path(args.out) if args.out else None)
    where = Path(args.out or args.dir) / "report.html"
    print(f"report of {report['campaign']['jobs_finished']} jobs: {where}")
    return 0
