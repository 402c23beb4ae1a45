"""What every command line of the toolkit shares: the top-level parser (`command_parser`: `--help`
showing each option's default, `--version`), argument types, options made from the config
dataclasses (`add_config_options` / `config_from_args`: the dataclass holds each default once), the
options every working command ends with (`add_run_options`: `--resume`, `--quiet`, the handler),
and the one way `main` reports errors (one line, exit 2, for bad input; 130 on Ctrl-C, work kept)."""

from __future__ import annotations

import argparse
import dataclasses
import errno
import sys
import types
import typing

from rasterize.errors import InputError


DISTRIBUTION = "riskmap-toolkit"     # the installed distribution (pyproject.toml's project.name)
QUIET_HELP = "no progress bar or progress lines"
# Where a parsed command line holds its command's words, outermost first: the top-level command,
# then the subcommand of a command group (`add_command_group`); error lines name the command by them.
COMMAND_DESTS = ("command", "guard_command", "figure")


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """`--help` that appends each option's default where it says something: not for switches,
    required options, positionals or a default of None or nothing, nor where the help already
    names its default (or says `%(default)s`)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (not action.option_strings or action.required or action.nargs == 0
                or default is None or default is False or default is argparse.SUPPRESS
                or (isinstance(default, (tuple, list)) and not default)
                or "default" in text.lower()):
            return text
        if isinstance(default, (tuple, list)):
            default = ",".join(str(v) for v in default)
        shown = str(default).replace("%", "%%")       # the help string is %-formatted afterwards
        return f"{text} (default: {shown})" if text else f"default: {shown}"


class CommandParser(argparse.ArgumentParser):
    """An ArgumentParser whose `--help` shows defaults (`DefaultsHelpFormatter`); the subcommand
    parsers made from it (`add_subparsers` makes them of the parent's class) are the same."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", DefaultsHelpFormatter)
        super().__init__(*args, **kwargs)


def package_version() -> str:
    """The installed toolkit's version (importlib.metadata), or a note that it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(DISTRIBUTION)
    except PackageNotFoundError:
        return "unknown (riskmap-toolkit is not installed; pip install -e .)"


def command_parser(prog: str, doc: str) -> CommandParser:
    """The top-level parser of a console command: `doc`'s first paragraph as its description,
    defaults in every `--help`, and `--version`."""
    parser = CommandParser(prog=prog, description=" ".join(doc.split("\n\n")[0].split()))
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}",
                        help=f"print the installed {DISTRIBUTION} version and exit")
    return parser


def add_command_group(subparsers, name: str, help: str, dest: str):
    """A command group (`riskmap guard`, `riskmap figures`): its parser under `subparsers`, and the
    subparsers of its required subcommand, whose choice lands in `dest` (one of `COMMAND_DESTS`, so
    that an error line names the whole command)."""
    if dest not in COMMAND_DESTS:
        raise ValueError(f"{dest!r} is not in COMMAND_DESTS: errors of `{name}` would not name its "
                         "subcommand")
    return subparsers.add_parser(name, help=help).add_subparsers(dest=dest, required=True)


def walk_commands(parser: argparse.ArgumentParser, path: str, summary: str = ""):
    """(command path, parser, one-line summary) for `parser` and every subcommand below it, nested
    ones included, in the order `--help` lists them (for the help tests and the docs reference)."""
    yield path, parser, summary
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help or "" for choice in action._choices_actions}
            for name, sub in action.choices.items():
                yield from walk_commands(sub, f"{path} {name}", helps.get(name, ""))


def add_run_options(parser: argparse.ArgumentParser, func, *, resume: str | None = None,
                    quiet: str = QUIET_HELP) -> None:
    """The tail every working command's parser ends with: `--resume` (when `resume`, its help text:
    what continuing keeps, is given), `--quiet` (help `quiet`) and `func`, the handler
    `run_command` calls."""
    if resume is not None:
        parser.add_argument("--resume", action="store_true", help=resume)
    parser.add_argument("--quiet", action="store_true", help=quiet)
    parser.set_defaults(func=func)


def _number(text: str, kind: type, ok, must: str):
    """`text` as `kind` if `ok(value)`, else an argparse error saying what it `must` be."""
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
    if not ok(value):
        raise argparse.ArgumentTypeError(f"{text} must be {must}")
    return value


def positive_int(text: str) -> int:
    return _number(text, int, lambda v: v >= 1, "at least 1")


def non_negative_int(text: str) -> int:
    return _number(text, int, lambda v: v >= 0, "0 or more")


def positive_float(text: str) -> float:
    """A finite number > 0 (NaN, inf, zero and negatives are refused by argparse)."""
    import math

    return _number(text, float, lambda v: math.isfinite(v) and v > 0, "a finite number > 0")


def _command_name(args: argparse.Namespace) -> str:
    """The command as typed: `collect`, `guard train`, `figures plans`."""
    words = (getattr(args, name, None) for name in COMMAND_DESTS)
    return " ".join(w for w in words if isinstance(w, str) and w)


def _file_in_the_way(path) -> str | None:
    """The regular file standing where `path` or one of its parent folders should be, if any."""
    from pathlib import Path

    for p in (Path(path), *Path(path).parents):
        try:
            if p.is_file():
                return str(p)
        except OSError:
            return None
    return None


def run_command(prog: str, parser: argparse.ArgumentParser, argv: list[str] | None) -> int:
    """Parse `argv`, run the chosen handler (`args.func`) and turn bad input into one line."""
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except InputError as err:
        command = _command_name(args)
        message = " ".join(str(err).split("\n"))          # one line, whatever the message
        print(f"{prog}{' ' + command if command else ''}: error: {message}", file=sys.stderr)
        return 2
    except OSError as err:
        # A path the system refused (missing parent, no permission, read-only or full disk):
        # one line naming it, not a traceback.
        command = _command_name(args)
        where = f"{err.filename}: " if err.filename else ""
        reason = err.strerror or str(err)
        blocker = (_file_in_the_way(err.filename) if err.filename
                   and err.errno in (errno.EEXIST, errno.ENOTDIR) else None)
        if blocker is not None:
            reason = f"{blocker} is a file, not a folder"
        if err.errno in (errno.ENOSPC, errno.EDQUOT):
            fix = "free some space and rerun with --resume (finished work is kept)"
        else:
            fix = "check that the path exists and that you may write there"
        print(f"{prog}{' ' + command if command else ''}: error: {where}{reason}; "
              f"{fix}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted; finished work is kept, rerun with --resume", file=sys.stderr)
        return 130


def comma_list(text: str) -> tuple[str, ...]:
    """`a,b,c` -> ("a", "b", "c"); empty items dropped."""
    return tuple(item.strip() for item in text.split(",") if item.strip())


def _option_type(hint):
    """The argparse type for a config field's annotation (X | None -> X; tuple[str, ...] -> a
    comma-separated list)."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if typing.get_origin(hint) in (typing.Union, types.UnionType) and len(args) == 1:
        return _option_type(args[0])
    if typing.get_origin(hint) is tuple:
        return comma_list
    return hint if hint in (int, float, str) else str


def add_config_options(parser: argparse.ArgumentParser, config_type: type, *names: str,
                       flags: dict[str, str] | None = None, help: dict[str, str] | None = None,
                       option_types: dict | None = None, choices: dict | None = None) -> None:
    """Add `--field-name` options for fields `names` of the frozen config dataclass `config_type`:
    type and default come from the dataclass (one source of truth), help from `help` or the field's
    `metadata["help"]`. `flags` renames an option, `option_types` overrides its argparse type (e.g.
    `positive_int`), `choices` limits its values. Read them back with `config_from_args`."""
    flags, help, option_types, choices = flags or {}, help or {}, option_types or {}, choices or {}
    hints = typing.get_type_hints(config_type)
    by_name = {f.name: f for f in dataclasses.fields(config_type)}
    for name in names:
        if name not in by_name:
            raise ValueError(f"{config_type.__name__} has no field {name!r}")
        field = by_name[name]
        if field.default is not dataclasses.MISSING:
            default, required = field.default, False
        elif field.default_factory is not dataclasses.MISSING:
            default, required = field.default_factory(), False
        else:
            default, required = None, True
        kwargs = {"dest": name, "type": option_types.get(name, _option_type(hints[name])),
                  "help": help.get(name, field.metadata.get("help"))}
        if hints[name] is bool and default is False:     # a switch, off unless named
            kwargs = {"dest": name, "action": "store_true", "help": kwargs["help"]}
        if name in choices:
            kwargs["choices"] = tuple(choices[name])
        if required:
            kwargs["required"] = True
        else:
            kwargs["default"] = default
        parser.add_argument(flags.get(name, "--" + name.replace("_", "-")), **kwargs)


def config_from_args(config_type: type, args: argparse.Namespace, **overrides):
    """`config_type` from the options `add_config_options` added (and `overrides`)."""
    values = {f.name: getattr(args, f.name) for f in dataclasses.fields(config_type)
              if hasattr(args, f.name)}
    return config_type(**{**values, **overrides})
