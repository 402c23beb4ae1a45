"""The same tiny campaign on a local Ray instance gives the same numbers as the local backend."""

import pytest

from adversary.campaign.run import RunOptions, run_campaign
from adversary.report.page import make_report
from tests.adversary.conftest import tiny_config

pytestmark = pytest.mark.slow


def test_ray_backend_matches_local(tiny_campaign, tmp_path):
    pytest.importorskip("ray")
    out = tmp_path / "ray"
    counts = run_campaign(tiny_config(), out, RunOptions(backend="ray", workers=2, progress=False))
    assert counts["finished"] == 12 and counts["failed"] == 0
    ray_results = make_report(out, tmp_path / "ray_report")["results"]
    local_results = make_report(tiny_campaign, tmp_path / "local_report")["results"]
    assert ray_results == local_results
