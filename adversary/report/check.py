"""Static checks of a report page: every image exists and decodes, every table has data rows."""

from __future__ import annotations

from html.parser import HTMLParser
from pathlib import Path


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images: list[str] = []
        self.tables: list[dict] = []       # {"id": str, "rows": data rows (with <td>)}
        self._open: list[dict] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append(attrs.get("src", ""))
        elif tag == "table":
            self._open.append({"id": attrs.get("id", f"table {len(self.tables) + len(self._open) + 1}"),
                               "rows": 0})
        elif tag == "td" and self._open:
            self._open[-1]["_td"] = True
        elif tag == "tr" and self._open:
            self._open[-1]["_td"] = False

    def handle_endtag(self, tag):
        if tag == "tr" and self._open and self._open[-1].pop("_td", False):
            self._open[-1]["rows"] += 1
        elif tag == "table" and self._open:
            table = self._open.pop()
            table.pop("_td", None)
            self.tables.append(table)


def page_summary(html_path: Path) -> dict:
    """{"images": [src], "tables": [{"id", "rows"}]} of a report page."""
    page = _Page()
    page.feed(Path(html_path).read_text())
    return {"images": page.images, "tables": page.tables}


def report_problems(html_path: Path) -> list[str]:
    """Human-readable problems; empty when every image decodes and every table has rows."""
    import matplotlib.image

    html_path = Path(html_path)
    summary = page_summary(html_path)
    problems = []
    if not summary["images"]:
        problems.append("the page has no images")
    for src in summary["images"]:
        path = html_path.parent / src
        try:
            image = matplotlib.image.imread(path)
            if image.shape[0] == 0 or image.shape[1] == 0:
                problems.append(f"image {src} is empty")
        except (OSError, ValueError, SyntaxError) as error:
            problems.append(f"image {src} does not load ({type(error).__name__})")
    for table in summary["tables"]:
        if table["rows"] == 0:
            problems.append(f"table {table['id']} has no rows")
    return problems
