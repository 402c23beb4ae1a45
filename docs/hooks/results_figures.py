"""MkDocs hook: the figures of the results pages, taken from experiments/results/ at build time.

The pages under `docs/results/` embed the PNG figures that `experiments/README.md` cites, with
relative links of the form `![...](figures/<path under experiments/results>.png)`. No copy of a
figure is committed under `docs/`: this hook reads every Markdown page of `docs/results/`, finds
those links, and adds each figure to the site as a file whose source is
`experiments/results/<path>` and whose place in the site is `results/figures/<path>` (the page's
relative link resolves there), so that `mkdocs build --strict` validates every link against a
file that exists. A link to a figure that is not under `experiments/results/` is reported as a
warning, which fails the strict build.

Registered under `hooks:` in mkdocs.yml.
"""

from __future__ import annotations

import re
from pathlib import Path

from mkdocs.plugins import get_plugin_logger
from mkdocs.structure.files import File, Files

log = get_plugin_logger(__name__)

PAGES_DIR = "results"                       # under docs_dir: the pages whose figures are added
SITE_DIR = "results/figures"                # where the figures land in the site
SOURCE = Path(__file__).resolve().parents[2] / "experiments" / "results"
FIGURE = re.compile(r"\]\(\s*(figures/[^)\s#]+\.png)\s*\)")   # ![alt](figures/....png)


def referenced_figures(docs_dir: Path) -> list[str]:
    """Every figure path (under experiments/results/, '/'-separated) that a results page links to,
    sorted and without repeats."""
    found = set()
    for page in sorted((docs_dir / PAGES_DIR).rglob("*.md")):
        for link in FIGURE.findall(page.read_text(encoding="utf-8")):
            # the link is relative to the page; every results page sits in docs/results/ itself
            found.add(link.removeprefix("figures/"))
    return sorted(found)


def on_files(files: Files, *, config) -> Files:
    docs_dir = Path(config["docs_dir"])
    for rel in referenced_figures(docs_dir):
        source = (SOURCE / rel).resolve()
        if SOURCE.resolve() not in source.parents or not source.is_file():
            log.warning("results page links to figures/%s, which is not a file under %s", rel, SOURCE)
            continue
        uri = f"{SITE_DIR}/{rel}"
        if files.get_file_from_path(uri) is not None:
            continue
        files.append(File.generated(config, uri, abs_src_path=str(source)))
    return files


def on_serve(server, *, config, builder):
    """`mkdocs serve` rebuilds when a figure changes."""
    server.watch(str(SOURCE))
    return server
