"""Open a stress-test report in headless Chromium: every image loaded, every table has rows.

    python experiments/check_report.py out/demo/report.html --screenshot out/demo/report_screenshot.png

Chromium (Debian: `apt-get install -y chromium`) loads a copy of the page with a small script
appended that, once everything has loaded, writes each <img>'s naturalWidth and each <table>'s
row count into the DOM; `--dump-dom` returns it. A second run takes a screenshot. The static
check (files exist and decode, tables have rows: adversary.report.check) runs first and also
without a browser (`--no-browser`). Exit status 0 only when no check failed.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from adversary.report.check import report_problems

_PROBE = """
<script>
window.addEventListener("load", function () {
  var out = {images: [], tables: []};
  document.querySelectorAll("img").forEach(function (img) {
    out.images.push({src: img.getAttribute("src"), width: img.naturalWidth, complete: img.complete});
  });
  document.querySelectorAll("table").forEach(function (t, i) {
    out.tables.push({id: t.id || ("table " + (i + 1)), rows: t.querySelectorAll("tr td").length ?
                     Array.from(t.querySelectorAll("tr")).filter(r => r.querySelector("td")).length : 0});
  });
  var pre = document.createElement("pre");
  pre.id = "report-check";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>
"""


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        if shutil.which(name):
            return shutil.which(name)
    return None


def _chromium(browser: str, *args: str, timeout_s: float = 120.0) -> str:
    command = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
               "--allow-file-access-from-files", *args]
    done = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"chromium exited {done.returncode}: {done.stderr.strip()[-300:]}")
    return done.stdout


def browser_problems(page: Path, browser: str) -> tuple[list[str], dict]:
    html = page.read_text()
    with tempfile.NamedTemporaryFile("w", suffix=".html", dir=page.parent, delete=False) as f:
        f.write(html.replace("</body>", _PROBE + "</body>"))
        probe_page = Path(f.name)
    try:
        dom = _chromium(browser, "--virtual-time-budget=20000", "--dump-dom", probe_page.as_uri())
    finally:
        probe_page.unlink(missing_ok=True)
    start = dom.find('<pre id="report-check">')
    if start < 0:
        return ["the browser did not run the page's load handler"], {}
    text = dom[start + len('<pre id="report-check">'): dom.index("</pre>", start)]
    import html as html_lib

    found = json.loads(html_lib.unescape(text))
    problems = [f"browser: image {i['src']} did not load" for i in found["images"] if not i["width"]]
    problems += [f"browser: table {t['id']} has no rows" for t in found["tables"] if not t["rows"]]
    return problems, found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("page", type=Path, help="report.html")
    parser.add_argument("--screenshot", type=Path, default=None, help="PNG to write (browser)")
    parser.add_argument("--window", default="1280,2400", help="screenshot size WIDTH,HEIGHT (px)")
    parser.add_argument("--no-browser", action="store_true", help="static checks only")
    args = parser.parse_args(argv)
    if not args.page.is_file():
        print(f"check_report: error: {args.page}: no such file", file=sys.stderr)
        return 2
    problems = report_problems(args.page)
    print(f"static: {len(problems)} problems")
    if not args.no_browser:
        browser = find_chromium()
        if browser is None:
            print("check_report: error: no chromium on PATH (apt-get install -y chromium)",
                  file=sys.stderr)
            return 2
        found_problems, found = browser_problems(args.page.resolve(), browser)
        problems += found_problems
        print(f"browser: {len(found.get('images', []))} images, {len(found.get('tables', []))} tables, "
              f"{len(found_problems)} problems")
        if args.screenshot is not None:
            args.screenshot.parent.mkdir(parents=True, exist_ok=True)
            _chromium(browser, f"--window-size={args.window}",
                      f"--screenshot={args.screenshot.resolve()}", args.page.resolve().as_uri())
            print(f"screenshot: {args.screenshot}")
    for problem in problems:
        print(f"  {problem}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
