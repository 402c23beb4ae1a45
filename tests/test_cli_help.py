"""Every option of every `riskmap` and `adversary` subcommand has help text, `--help` shows the
defaults that say something (riskmap.infra.cli.DefaultsHelpFormatter), and `--version` prints the
installed distribution's version."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from importlib.metadata import version

import pytest

from adversary.cli import build_parser as adversary_parser
from adversary.cli import main as adversary_main
from riskmap.cli import build_parser as riskmap_parser
from riskmap.cli import main as riskmap_main
from riskmap.infra.cli import DISTRIBUTION, DefaultsHelpFormatter, walk_commands

_NO_HELP_NEEDED = (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)


def _parsers():
    return [(path, parser) for root, name in ((riskmap_parser(), "riskmap"), (adversary_parser(), "adversary"))
            for path, parser, _ in walk_commands(root, name)]


def _options(parser: argparse.ArgumentParser):
    return [a for a in parser._actions if not isinstance(a, _NO_HELP_NEEDED)]


def test_the_walk_reaches_every_command():
    paths = {path for path, _ in _parsers()}
    assert {"riskmap collect", "riskmap guard train", "riskmap figures plans", "riskmap check-planner",
            "adversary attack", "adversary harden", "adversary export"} <= paths
    assert len(paths) > 25


def test_every_option_has_help_text():
    missing = [f"{path} {'/'.join(a.option_strings) or a.dest}"
               for path, parser in _parsers() for a in _options(parser)
               if not (a.help and a.help.strip()) or a.help == argparse.SUPPRESS]
    assert not missing, "options without help text:\n" + "\n".join(missing)


def test_help_shows_meaningful_defaults_once(monkeypatch):
    monkeypatch.setenv("COLUMNS", "1000")                  # one line per option: nothing wrapped
    for path, parser in _parsers():
        text = parser.format_help()                        # also: every help string %-formats
        for noise in ("(default: None)", "(default: False)", "(default: ())", "(default: [])",
                      "(default: )"):
            assert noise not in text, f"{path} --help: {noise}"
        formatter = DefaultsHelpFormatter(path)
        for action in _options(parser):
            shown = formatter._get_help_string(action)
            if "default" in action.help.lower():            # the help names its default itself
                assert shown == action.help, f"{path} {action.option_strings}: default twice"
            assert shown.lower().count("(default: ") <= 1
            if (action.option_strings and not action.required and action.nargs != 0
                    and isinstance(action.default, (int, float, str)) and action.default is not False
                    and "default" not in action.help.lower()):
                assert shown.endswith(f"(default: {action.default})"), (path, action.option_strings)


def test_defaults_appear_in_the_printed_help(monkeypatch, capsys):
    monkeypatch.setenv("COLUMNS", "1000")
    with pytest.raises(SystemExit) as exit_info:
        riskmap_main(["drive", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert re.search(r"--seed SEED +.*\(default: 0\)$", out, re.MULTILINE)
    assert "--resume" in out and "default: False" not in out
    with pytest.raises(SystemExit):
        adversary_main(["attack", "--help"])
    out = capsys.readouterr().out
    assert re.search(r"who becomes the adversary: .*\(default: crash\)$", out, re.MULTILINE)
    assert "default 2)" in out and "default 2) (default" not in out        # --replan-hz: once


@pytest.mark.parametrize("main, prog", [(riskmap_main, "riskmap"), (adversary_main, "adversary")])
def test_version(main, prog, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"{prog} {version(DISTRIBUTION)}"


@pytest.mark.parametrize("prog", ["riskmap", "adversary"])
def test_version_through_the_entry_point(prog):
    result = subprocess.run([sys.executable, "-m", prog, "--version"], capture_output=True, text=True,
                            timeout=120, check=False)
    assert result.returncode == 0 and result.stdout.strip() == f"{prog} {version(DISTRIBUTION)}"


@pytest.mark.parametrize("build", [riskmap_parser, adversary_parser])
def test_the_description_is_whole_sentences(build):
    description = build().description
    assert description.endswith(".") and "\n" not in description
