"""The `adversary` command line: stress-test campaigns, their reports, and scenario search.

Each subcommand lives in its own module (`cmd_*.py`) with `add_parser(subparsers)`, which sets
`handler`; this file only lists them.
"""

from __future__ import annotations

import argparse
import sys

from rasterize.errors import InputError


def build_parser() -> argparse.ArgumentParser:
    from adversary import cmd_crash, cmd_guard_data, cmd_report, cmd_search, cmd_stress_test

    parser = argparse.ArgumentParser(prog="adversary", description=__doc__.splitlines()[0])
    subparsers = parser.add_subparsers(dest="command", required=True)
    cmd_stress_test.add_parser(subparsers)
    cmd_report.add_parser(subparsers)
    cmd_search.add_parsers(subparsers)
    cmd_crash.add_parsers(subparsers)
    cmd_guard_data.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except InputError as error:
        print(f"adversary {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"adversary {args.command}: interrupted; finished work is kept, rerun with --resume",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
