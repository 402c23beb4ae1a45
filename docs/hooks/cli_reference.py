"""MkDocs hook: the command-line reference, generated at build time from the argparse parsers.

`riskmap.cli.build_parser` and `adversary.cli.build_parser` are the one source of truth for every
command's options; this hook walks them (every subcommand, nested ones such as `riskmap guard
train` included) and replaces the marker `<!-- cli-reference -->` in `reference/cli.md` with one
section per command: its summary, its usage line and a table of its options with their help text
and defaults, exactly as `--help` shows them (`riskmap.infra.cli.DefaultsHelpFormatter`). Nothing
it generates is written to disk or committed.

It also replaces `<!-- planner-declarations -->` in `reference/api.md` with the table of a
planner's optional declarations, made by `riskmap.sim.loop.plan.declarations_table` from
`PlannerTraits` (the same table docs/guide/your-own-planner.md carries, checked by a test).

Registered under `hooks:` in mkdocs.yml.
"""

from __future__ import annotations

import argparse
import html

MARKER = "<!-- cli-reference -->"
PAGE = "reference/cli.md"
DECLARATIONS_MARKER = "<!-- planner-declarations -->"
DECLARATIONS_PAGE = "reference/api.md"
USAGE_WIDTH = 78                       # characters per usage line (fits the page), whatever the terminal


def command_parsers():
    """Every (path, parser, summary) of the two console commands."""
    from adversary.cli import build_parser as adversary_parser
    from riskmap.cli import build_parser as riskmap_parser
    from riskmap.infra.cli import walk_commands

    return [*walk_commands(riskmap_parser(), "riskmap"), *walk_commands(adversary_parser(), "adversary")]


def documented_actions(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options and positionals a reader needs: all but -h/--help and the subcommand slot."""
    return [a for a in parser._actions
            if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))]


def anchor(path: str) -> str:
    """The id of a command's section: `riskmap guard train` -> `riskmap-guard-train`."""
    return path.replace(" ", "-")


def _usage(parser: argparse.ArgumentParser) -> str:
    formatter = parser.formatter_class(prog=parser.prog, width=USAGE_WIDTH)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups)
    return formatter.format_help().strip()


def _invocation(action: argparse.Action, formatter: argparse.HelpFormatter) -> str:
    """The option's first cell as HTML: each option string, then its argument, as `--help` writes
    them (`-q, --quiet`, `--seed SEED`, `--from-commonroad DIR_OR_FILE [DIR_OR_FILE ...]`), each
    in its own <code> so that a line breaks only between them; a positional by its name."""
    if not action.option_strings:
        return f"<code>{html.escape(formatter._format_action_invocation(action))}</code>"
    cell = ", ".join(f"<code>{html.escape(s)}</code>" for s in action.option_strings)
    if action.nargs != 0:
        argument = formatter._format_args(action, formatter._get_default_metavar_for_optional(action))
        cell += f" <code>{html.escape(argument)}</code>"
    return cell


def _help(action: argparse.Action, formatter: argparse.HelpFormatter) -> str:
    """The help text with its default appended, %-expanded, as `--help` prints it."""
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    return " ".join(formatter._expand_help(action).split())


def _section(path: str, parser: argparse.ArgumentParser, summary: str) -> str:
    formatter = parser.formatter_class(prog=parser.prog)
    depth = "#" * (2 + min(path.count(" "), 2))   # ## riskmap, ### riskmap guard, #### riskmap guard train
    lines = [f'{depth} `{path}` {{ #{anchor(path)} }}', ""]
    text = summary or parser.description or ""
    if text:
        lines += [html.escape(" ".join(text.split())), ""]
    lines += ["```text", _usage(parser), "```", ""]
    subcommands = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    for action in subcommands:
        names = ", ".join(f'<a href="#{anchor(f"{path} {n}")}"><code>{n}</code></a>'
                          for n in action.choices)
        lines += [f"<p>Subcommands: {names}.</p>", ""]
    actions = documented_actions(parser)
    if actions:
        rows = []
        for action in actions:
            required = " <em>(required)</em>" if action.option_strings and action.required else ""
            rows.append(f"<tr><td>{_invocation(action, formatter)}{required}</td>"
                        f"<td>{html.escape(_help(action, formatter))}</td></tr>")
        lines += ["<table>", "<thead><tr><th>option</th><th>meaning</th></tr></thead>",
                  "<tbody>", *rows, "</tbody>", "</table>", ""]
    return "\n".join(lines)


def render() -> str:
    """The whole generated reference: one section per command, in `--help` order."""
    return "\n".join(_section(path, parser, summary) for path, parser, summary in command_parsers())


def on_page_markdown(markdown: str, page, config, files) -> str:
    generated = {PAGE: (MARKER, render), DECLARATIONS_PAGE: (DECLARATIONS_MARKER, _declarations)}
    if page.file.src_uri not in generated:
        return markdown
    marker, make = generated[page.file.src_uri]
    if marker not in markdown:
        raise ValueError(f"{page.file.src_uri} lost its marker {marker}: the generated part has nowhere to go")
    return markdown.replace(marker, make())


def _declarations() -> str:
    from riskmap.sim.loop.plan import declarations_table

    return declarations_table()
