"""The example plug-in (examples/gap_keeper), installed as a user would install it, is evaluated
and stress-tested with no change to the toolkit; a planner that raises fails its own jobs only."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The example package installed (its entry point with it) into a folder of its own."""
    target = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                           "--no-build-isolation", "--target", str(target),
                           str(ROOT / "examples" / "gap_keeper")],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return target


def _run(installed, *argv, cwd):
    env = {**os.environ, "OMP_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join([str(installed), str(ROOT)])}
    return subprocess.run([sys.executable, "-m", *argv], cwd=cwd, env=env, capture_output=True,
                          text=True, check=False, timeout=600)


@pytest.mark.slow
def test_the_example_is_evaluated_through_its_entry_point(installed, tmp_path):
    done = _run(installed, "riskmap", "evaluate", "--planners", "gap-keeper:25,cv",
                "--env", "highway-v0", "--episodes", "2", "--episode-s", "8",
                "--out", str(tmp_path / "eval"), "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "| gap-keeper-25 | 2 |" in done.stdout          # the display name of the SPEC gap-keeper:25
    results = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert "gap-keeper:25" in json.dumps(results)


@pytest.mark.slow
def test_the_example_is_stress_tested_and_a_raising_planner_fails_only_its_jobs(installed, tmp_path):
    config = tmp_path / "campaign.yaml"
    config.write_text(
        "name: plugin\nseed: 0\n"
        "planners: ['gap-keeper:25', 'py:riskmap_example_planner:GapKeeper?desired_speed=20', "
        "'py:tests.broken_planners:Broken?fault=raise']\n"
        "scenarios:\n  - {env: highway-v0, seed: 0, episodes: 1}\n"
        "attacks:\n  - {name: natural}\n  - {name: aggressive_neighbour}\n"
        "budget: {episode_s: 3.0}\nreport: {gallery: 1}\n")
    out = tmp_path / "stress"
    done = _run(installed, "adversary", "stress-test", "--config", str(config), "--out", str(out),
                "--workers", "1", cwd=ROOT)
    assert done.returncode == 0, done.stderr
    records = [json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))]
    assert len(records) == 6
    by_planner = {}
    for record in records:
        by_planner.setdefault(record["planner"], []).append(record["status"])
    assert by_planner["gap-keeper:25"] == ["ok", "ok"]
    assert by_planner["py:riskmap_example_planner:GapKeeper?desired_speed=20"] == ["ok", "ok"]
    assert all(s != "ok" for s in by_planner["py:tests.broken_planners:Broken?fault=raise"])
    report = _run(installed, "adversary", "report", str(out), "--out", str(tmp_path / "report"),
                  cwd=ROOT)
    assert report.returncode == 0, report.stderr
    assert "gap-keeper:25" in (tmp_path / "report" / "report.html").read_text()
