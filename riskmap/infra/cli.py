"""What every command line of the toolkit shares: argument types and the one way `main` reports
errors (one line, exit 2, for bad input; 130 on Ctrl-C, finished work kept)."""

from __future__ import annotations

import argparse
import sys

from rasterize.errors import InputError


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} must be at least 1")
    return value


def run_command(prog: str, parser: argparse.ArgumentParser, argv: list[str] | None) -> int:
    """Parse `argv`, run the chosen handler (`args.func`) and turn bad input into one line."""
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except InputError as err:
        command = getattr(args, "command", None)
        print(f"{prog}{' ' + command if command else ''}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted; finished work is kept, rerun with --resume", file=sys.stderr)
        return 130
