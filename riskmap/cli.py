"""The `riskmap` command line: collect demonstrations, train planners, drive and evaluate them,
export figures, and the neuro-symbolic guard.

Each capability's folder owns its subcommands (`*/cli.py`); this file only lists them."""

from __future__ import annotations

import argparse

from riskmap.infra.cli import command_parser, run_command


def build_parser() -> argparse.ArgumentParser:
    from riskmap.data import cli as data_cli
    from riskmap.evaluation import cli as evaluation_cli
    from riskmap.figures import cli as figures_cli
    from riskmap.guard import cli as guard_cli
    from riskmap.training import cli as training_cli

    parser = command_parser("riskmap", __doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    for module in (data_cli, training_cli, evaluation_cli, figures_cli, guard_cli):
        module.add_parsers(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    return run_command("riskmap", build_parser(), argv)
