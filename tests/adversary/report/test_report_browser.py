"""The report as a browser sees it: headless Chromium loads every image and finds every table
filled. Skipped where no Chromium is installed, except in CI, where `.ci/run` installs it."""

import os
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
    shot = tmp_path / "shot.png"
    done = subprocess.run([sys.executable, str(CHECK), str(tmp_path / "report" / "report.html"),
                           "--screenshot", str(shot)], capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 problems" in done.stdout and shot.stat().st_size > 10_000
