"""The documentation works as written: docs/quickstart.md runs, and the site builds.

`test_the_quickstart_runs_verbatim` takes every ```bash block of docs/quickstart.md, in order,
and runs its commands exactly as written, one bash process for the whole page (so that
`source .venv/bin/activate` carries over as it does for a reader), stopping at the first command
that exits non-zero and naming it. The installation lines are skipped (`make setup`, `python3 -m
venv`, and every `pip install` line): they would reinstall the environment the tests already run
in.

Where it runs: the page's commands are relative to the repository root and write only under
`out/quickstart/`. Rather than writing there, they run in a fresh temporary directory that
stands in for the root: `checkpoints/`, `experiments/`, `examples/` and `tests/` (for the
CommonRoad fixtures) are symlinks to the repository's, which the commands only read, and `.venv`
is a symlink to the environment running the tests (its `bin/activate`). Every output therefore
lands in the temporary directory, and the repository is left as it was. The test checks that
every `--out` on the page lies under `out/quickstart/`, that the folders read through the
symlinks have the same files afterwards, and that each step's main output exists. Bytecode
writing is switched off, so that importing `examples/gap_keeper` through the symlink leaves no
`__pycache__` in the repository.

It takes about five minutes on a 2-core CPU (the page's own timings add up to that), so it is
marked `slow`.

`test_the_site_builds_strictly_with_every_option` runs `mkdocs build --strict` into tmp_path and
checks that the generated command-line reference has a section for every command and subcommand
(walking the parsers as tests/test_cli_help.py does) and, in that section, every option string of
that command. It is skipped when MkDocs and its plug-ins are not installed (the `docs` extra).
"""

from __future__ import annotations

import argparse
import html
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
QUICKSTART = ROOT / "docs" / "quickstart.md"
LINKED = ("checkpoints", "experiments", "examples", "tests")   # read, never written, by the page
OUT_PREFIX = "out/quickstart/"
INSTALL = re.compile(r"^\s*(make setup\b|python3? -m venv\b|\S*pip install\b|\S*python3? -m pip install\b)")


def bash_blocks(text: str) -> list[str]:
    """The body of every ```bash fenced block, in order."""
    return re.findall(r"^```bash\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)


def commands(block: str) -> list[str]:
    """The commands of a block, each as written (continuation lines kept with their backslashes);
    blank lines and whole-line comments are not commands."""
    found, current = [], []
    for line in block.splitlines():
        if not current and (not line.strip() or line.lstrip().startswith("#")):
            continue
        current.append(line)
        if not line.rstrip().endswith("\\"):
            found.append("\n".join(current))
            current = []
    assert not current, f"a command ends in a line continuation: {current}"
    return found


def quickstart_commands() -> tuple[list[str], list[str]]:
    """(commands to run, installation commands skipped), in the page's order."""
    run, skipped = [], []
    for block in bash_blocks(QUICKSTART.read_text()):
        for command in commands(block):
            (skipped if INSTALL.match(command) else run).append(command)
    return run, skipped


def _words(command: str) -> list[str]:
    return shlex.split(command.replace("\\\n", " "), comments=True)


def test_the_page_has_what_the_test_expects():
    run, skipped = quickstart_commands()
    assert any(c.startswith("make setup") for c in skipped)
    assert all("pip install" in c or "venv" in c or "make setup" in c for c in skipped)
    assert run and run[0].startswith("source .venv/bin/activate")
    programs = {_words(c)[0] if "=" not in _words(c)[0] else _words(c)[1] for c in run}
    assert {"riskmap", "adversary"} <= programs
    for command in run:                      # every output goes under out/quickstart/
        words = _words(command)
        outs = [words[i + 1] for i, w in enumerate(words[:-1]) if w == "--out"]
        if words[:2] == ["adversary", "report"]:
            outs.append(words[2])
        for out in outs:
            assert out.startswith(OUT_PREFIX), f"{command!r} writes outside {OUT_PREFIX}"


def _listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")
            if "__pycache__" not in p.parts and not p.name.endswith(".pyc")}


def _stand_in_root(root: Path) -> None:
    """`root` made to look like the repository root for the page's commands (module docstring)."""
    root.mkdir()
    for name in LINKED:
        (root / name).symlink_to(ROOT / name, target_is_directory=True)
    venv = Path(sys.prefix)
    if (venv / "bin" / "activate").is_file():
        (root / ".venv").symlink_to(venv, target_is_directory=True)
    else:                                    # not a venv: an activate that puts this Python first
        (root / ".venv" / "bin").mkdir(parents=True)
        (root / ".venv" / "bin" / "activate").write_text(
            f'export PATH={shlex.quote(str(Path(sys.executable).parent))}:"$PATH"\n')


@pytest.mark.slow
def test_the_quickstart_runs_verbatim(tmp_path):
    run, _ = quickstart_commands()
    root = tmp_path / "repo"
    _stand_in_root(root)
    before = {name: _listing(ROOT / name) for name in ("checkpoints", "examples", "tests/fixtures",
                                                       "experiments/campaigns")}
    script = []
    for number, command in enumerate(run, 1):
        script += [f"echo {shlex.quote(f'[quickstart {number}/{len(run)}] {command}')} >&2",
                   command,
                   f"rc=$?; if [ $rc -ne 0 ]; then echo {shlex.quote(f'QUICKSTART FAILED: command {number}:')} "
                   f"{shlex.quote(command)} \"(exit $rc)\" >&2; exit 1; fi"]
    (tmp_path / "quickstart.sh").write_text("\n".join(script) + "\n")
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1",
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    env.pop("RISKMAP_KILL_AT", None)
    done = subprocess.run(["bash", str(tmp_path / "quickstart.sh")], cwd=root, env=env,
                          capture_output=True, text=True, timeout=1800, check=False)
    assert done.returncode == 0, f"{done.stderr[-6000:]}\n--- stdout ---\n{done.stdout[-3000:]}"
    out = root / "out" / "quickstart"
    for made in ("data/highway/manifest.json", "runs/highway/best.safetensors",
                 "figures/scenes", "figures/plans_mine", "figures/plans_shipped",
                 "drive/highway/summary.json", "drive/highway_idm/summary.json",
                 "eval/us101/results.json", "eval/gap_keeper/results.json",
                 "stress/report.html"):
        assert (out / made).exists(), f"the quickstart did not make out/quickstart/{made}"
    assert list((out / "figures" / "plans_mine").glob("*.png"))
    after = {name: _listing(ROOT / name) for name in before}
    assert after == before, "the quickstart wrote into the repository"


# --- the site -------------------------------------------------------------------------------

def _parsers():
    from adversary.cli import build_parser as adversary_parser
    from riskmap.cli import build_parser as riskmap_parser
    from riskmap.infra.cli import walk_commands

    return [(path, parser) for parser_of in (riskmap_parser(), adversary_parser())
            for path, parser, _ in walk_commands(parser_of, parser_of.prog)]


def _sections(page: str) -> dict[str, str]:
    """The built CLI page cut at its command headings: {heading id: that section's HTML}."""
    heads = list(re.finditer(r'<h[234] id="([^"]+)"', page))
    return {m.group(1): page[m.end():(heads[i + 1].start() if i + 1 < len(heads) else len(page))]
            for i, m in enumerate(heads)}


def test_the_site_builds_strictly_with_every_option(tmp_path):
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        pytest.importorskip(module, reason="the docs extra is not installed (pip install -e '.[docs]')")
    site = tmp_path / "site"
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
                           str(ROOT / "mkdocs.yml"), "--site-dir", str(site)],
                          cwd=ROOT, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-6000:]
    assert "WARNING" not in done.stderr, done.stderr
    for page in ("index.html", "quickstart/index.html", "results/index.html", "reference/api/index.html"):
        assert (site / page).is_file(), page
    sections = _sections((site / "reference" / "cli" / "index.html").read_text())
    missing = []
    for path, parser in _parsers():
        anchor = path.replace(" ", "-")
        assert anchor in sections, f"no section for `{path}` in the CLI reference"
        section = sections[anchor]
        formatter = argparse.HelpFormatter(parser.prog)
        for action in parser._actions:
            if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            wanted = action.option_strings or [formatter._format_action_invocation(action)]
            missing += [f"{path} {s}" for s in wanted           # in an option cell: <code>--seed SEED</code>
                        if not re.search(r"(?:<code>|, )" + re.escape(html.escape(s)) + r"(?=[ ,<])", section)]
    assert not missing, "options missing from the built CLI reference:\n" + "\n".join(missing)
