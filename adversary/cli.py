"""The `adversary` command line: stress-test campaigns, their reports, scenario search and CRASH.

Each capability's folder owns its subcommands (`*/cli.py`, `add_parsers(subparsers)`); this file
only lists them.
"""

from __future__ import annotations

import argparse

from riskmap.infra.cli import command_parser, run_command


def build_parser() -> argparse.ArgumentParser:
    from adversary.attacks import guard_data as guard_data_cli
    from adversary.campaign import cli as campaign_cli
    from adversary.crash import cli as crash_cli
    from adversary.export import cli as export_cli
    from adversary.harden import cli as harden_cli
    from adversary.report import cli as report_cli
    from adversary.search import cli as search_cli

    parser = command_parser("adversary", __doc__)
    subparsers = parser.add_subparsers(dest="command", required=True)
    for module in (campaign_cli, report_cli, search_cli, crash_cli, guard_data_cli, harden_cli,
                   export_cli):
        module.add_parsers(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    return run_command("adversary", build_parser(), argv)
