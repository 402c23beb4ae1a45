"""Open a stress-test report and every job page in headless Chromium: every image loaded, every
table has rows, every GIF animates.

    python experiments/check_report.py out/demo/report.html --screenshot out/demo/report_top.png \
        --job-screenshot out/demo/report_job_page.png

Chromium (Debian: `apt-get install -y chromium`) loads one probe page, written next to the
report for the run, that holds the report and each job page it links to (jobs/*.html) in
iframes; once everything has loaded, a script writes each page's <img> naturalWidths and
<table> row counts into the DOM, which `--dump-dom` returns (one browser start for all pages).
The static checks (adversary.report.check.site_problems: files exist and decode, every GIF has
at least two frames, tables have rows, linked pages exist) run first and also without a browser
(`--no-browser`). Screenshots (`--window-size`, default 1280x1600) show the report's top and one
job page (the first the report links to, the worst scene's, unless `--job` names one). Exit
status 0 only when no check failed.
"""

from __future__ import annotations

import argparse
import html as html_lib
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from adversary.report.check import image_problem, job_pages, page_summary, site_problems

_PROBE = """<!DOCTYPE html>
<html><head><meta charset="utf-8"></head><body>
{frames}
<script>
window.addEventListener("load", function () {{
  var out = [];
  document.querySelectorAll("iframe").forEach(function (frame) {{
    var page = {{page: frame.getAttribute("src"), images: [], tables: []}};
    try {{
      var doc = frame.contentDocument;
      doc.querySelectorAll("img").forEach(function (img) {{
        page.images.push({{src: img.getAttribute("src"), width: img.naturalWidth, complete: img.complete}});
      }});
      doc.querySelectorAll("table").forEach(function (t, i) {{
        page.tables.push({{id: t.id || ("table " + (i + 1)),
                          rows: Array.from(t.querySelectorAll("tr")).filter(r => r.querySelector("td")).length}});
      }});
    }} catch (e) {{ page.error = String(e); }}
    out.push(page);
  }});
  var pre = document.createElement("pre");
  pre.id = "report-check";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
}});
</script>
</body></html>
"""


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        if shutil.which(name):
            return shutil.which(name)
    return None


def _chromium(browser: str, *args: str, timeout_s: float = 180.0) -> str:
    command = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
               "--allow-file-access-from-files", *args]
    done = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"chromium exited {done.returncode}: {done.stderr.strip()[-300:]}")
    return done.stdout


def browser_problems(page: Path, browser: str) -> tuple[list[str], list[dict]]:
    """(problems, what the browser found on each page) for the report and its job pages."""
    pages = [page.name] + [p.relative_to(page.parent).as_posix() for p in job_pages(page)
                           if p.is_file()]
    frames = "\n".join(f'<iframe src="{html_lib.escape(p)}" width="1280" height="900"></iframe>'
                       for p in pages)
    with tempfile.NamedTemporaryFile("w", suffix=".html", prefix=".probe-", dir=page.parent,
                                     delete=False) as f:
        f.write(_PROBE.format(frames=frames))
        probe_page = Path(f.name)
    try:
        dom = _chromium(browser, "--virtual-time-budget=30000", "--dump-dom", probe_page.as_uri())
    finally:
        probe_page.unlink(missing_ok=True)
    start = dom.find('<pre id="report-check">')
    if start < 0:
        return ["the browser did not run the probe page's load handler"], []
    text = dom[start + len('<pre id="report-check">'): dom.index("</pre>", start)]
    found = json.loads(html_lib.unescape(text))
    problems = []
    for p in found:
        if "error" in p:
            problems.append(f"browser: could not read {p['page']}: {p['error']}")
        problems += [f"browser: {p['page']}: image {i['src']} did not load" for i in p["images"]
                     if not i["width"]]
        problems += [f"browser: {p['page']}: table {t['id']} has no rows" for t in p["tables"]
                     if not t["rows"]]
    if found and not found[0]["images"]:
        problems.append("browser: the report shows no image")
    return problems, found


def gif_report(page: Path) -> list[tuple[str, int]]:
    """(path, frames) of every GIF the report and its job pages show."""
    from PIL import Image

    out = {}
    for html in [page] + [p for p in job_pages(page) if p.is_file()]:
        for src in page_summary(html)["images"]:
            path = (html.parent / src).resolve()
            if path.suffix.lower() == ".gif" and path not in out and image_problem(path) is None:
                with Image.open(path) as image:
                    out[path] = getattr(image, "n_frames", 1)
    return [(str(p.relative_to(page.parent.resolve())), n) for p, n in out.items()]


def screenshot(browser: str, page: Path, path: Path, window: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    _chromium(browser, f"--window-size={window}", f"--screenshot={path.resolve()}", page.resolve().as_uri())
    print(f"screenshot: {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("page", type=Path, help="report.html")
    parser.add_argument("--screenshot", type=Path, default=None, help="PNG of the report's top (browser)")
    parser.add_argument("--job-screenshot", type=Path, default=None, help="PNG of one job page (browser)")
    parser.add_argument("--job", default=None, help="job id of --job-screenshot (default: the first linked)")
    parser.add_argument("--window", default="1280,1600", help="screenshot size WIDTH,HEIGHT (px)")
    parser.add_argument("--no-browser", action="store_true", help="static checks only")
    args = parser.parse_args(argv)
    if not args.page.is_file():
        print(f"check_report: error: {args.page}: no such file", file=sys.stderr)
        return 2
    page = args.page.resolve()
    problems = site_problems(page)
    pages = job_pages(page)
    gifs = gif_report(page)
    print(f"static: report and {len(pages)} job pages, {len(gifs)} GIFs "
          f"({', '.join(str(n) for _, n in gifs) or 'no'} frames), {len(problems)} problems")
    if not args.no_browser:
        browser = find_chromium()
        if browser is None:
            print("check_report: error: no chromium on PATH (apt-get install -y chromium)",
                  file=sys.stderr)
            return 2
        found_problems, found = browser_problems(page, browser)
        problems += found_problems
        print(f"browser: {len(found)} pages, {sum(len(p['images']) for p in found)} images, "
              f"{sum(len(p['tables']) for p in found)} tables, {len(found_problems)} problems")
        if args.screenshot is not None:
            screenshot(browser, page, args.screenshot, args.window)
        if args.job_screenshot is not None:
            chosen = page.parent / "jobs" / f"{args.job}.html" if args.job else (pages[0] if pages else None)
            if chosen is None or not chosen.is_file():
                problems.append(f"no job page to screenshot ({chosen})")
            else:
                screenshot(browser, chosen, args.job_screenshot, args.window)
    for problem in problems:
        print(f"  {problem}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
