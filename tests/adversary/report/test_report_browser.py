"""The report as a browser sees it: headless Chromium loads every image of the report and of
every job page, and finds every table filled; every GIF shown has at least two frames. Skipped
where no Chromium is installed, except in CI, where `.ci/run` installs it."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from adversary.report.page import make_report

pytestmark = pytest.mark.slow
CHECK = Path(__file__).resolve().parents[3] / "experiments" / "check_report.py"


def test_chromium_loads_every_image_and_table_of_the_report(tiny_campaign, tmp_path):
    if not any(shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome")):
        if os.environ.get("CI") == "true":
            pytest.fail("no chromium on PATH in CI; .ci/run installs Debian's chromium")
        pytest.skip("no chromium on PATH (apt-get install -y chromium)")
    make_report(tiny_campaign, tmp_path / "report")
    shot, job_shot = tmp_path / "shot.png", tmp_path / "job.png"
    done = subprocess.run([sys.executable, str(CHECK), str(tmp_path / "report" / "report.html"),
                           "--screenshot", str(shot), "--job-screenshot", str(job_shot)],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    jobs = len(list((tmp_path / "report" / "jobs").glob("*.html")))
    assert jobs == 12
    static = re.search(r"static: report and (\d+) job pages, (\d+) GIFs \(([\d, ]+) frames\), 0 problems",
                       done.stdout)
    assert static and int(static.group(1)) == jobs and int(static.group(2)) >= 1, done.stdout
    assert all(int(n) >= 2 for n in static.group(3).split(", "))
    browser = re.search(r"browser: (\d+) pages, (\d+) images, \d+ tables, 0 problems", done.stdout)
    assert browser and int(browser.group(1)) == jobs + 1, done.stdout
    assert shot.stat().st_size > 10_000 and job_shot.stat().st_size > 10_000
