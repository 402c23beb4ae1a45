"""Static checks of a report and its job pages: every image exists and decodes, every animated GIF
has at least two frames, every table has data rows, every linked job page exists and passes the
same checks."""

from __future__ import annotations

from html.parser import HTMLParser
from pathlib import Path


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images: list[str] = []
        self.links: list[str] = []
        self.tables: list[dict] = []       # {"id": str, "rows": data rows (with <td>)}
        self._open: list[dict] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append(attrs.get("src", ""))
        elif tag == "a" and attrs.get("href"):
            self.links.append(attrs["href"])
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
    """{"images": [src], "links": [href], "tables": [{"id", "rows"}]} of a report page."""
    page = _Page()
    page.feed(Path(html_path).read_text())
    return {"images": page.images, "links": page.links, "tables": page.tables}


MIN_GIF_FRAMES = 2


def image_problem(path: Path) -> str | None:
    """Why the image at `path` is unusable (missing, undecodable, empty, a GIF of one frame), or
    None."""
    from PIL import Image

    try:
        with Image.open(path) as image:
            image.load()
            if image.width == 0 or image.height == 0:
                return "is empty"
            if image.format == "GIF" and getattr(image, "n_frames", 1) < MIN_GIF_FRAMES:
                return f"is a GIF of {getattr(image, 'n_frames', 1)} frame (at least {MIN_GIF_FRAMES} wanted)"
    except (OSError, ValueError, SyntaxError) as error:
        return f"does not load ({type(error).__name__})"
    return None


def report_problems(html_path: Path, require_images: bool = True) -> list[str]:
    """Human-readable problems of one page; empty when every image decodes (GIFs: with at least
    two frames) and every table has rows."""
    html_path = Path(html_path)
    summary = page_summary(html_path)
    problems = []
    if require_images and not summary["images"]:
        problems.append("the page has no images")
    for src in summary["images"]:
        problem = image_problem(html_path.parent / src)
        if problem:
            problems.append(f"image {src} {problem}")
    for table in summary["tables"]:
        if table["rows"] == 0:
            problems.append(f"table {table['id']} has no rows")
    return problems


def job_pages(html_path: Path) -> list[Path]:
    """The job pages a report links to (jobs/*.html), each once, in link order."""
    html_path = Path(html_path)
    links = [h.split("#")[0] for h in page_summary(html_path)["links"]]
    pages = dict.fromkeys(h for h in links if h.startswith("jobs/") and h.endswith(".html"))
    return [html_path.parent / h for h in pages]


def site_problems(html_path: Path) -> list[str]:
    """report_problems of the report and of every job page it links to (a page may have no
    images: a failed job's has only its record), and linked pages that do not exist."""
    html_path = Path(html_path)
    problems = report_problems(html_path)
    pages = job_pages(html_path)
    if not pages:
        problems.append("the report links to no job page")
    for page in pages:
        if not page.is_file():
            problems.append(f"job page {page.relative_to(html_path.parent)} does not exist")
            continue
        problems += [f"{page.relative_to(html_path.parent)}: {p}"
                     for p in report_problems(page, require_images=False)]
    return problems
