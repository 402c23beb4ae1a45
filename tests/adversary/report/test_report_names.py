"""A campaign report shows planners by their display names (riskmap.registry.display_names) in
its tables, summary and job pages, and keeps each SPEC beside the name in report.json."""

import json

from adversary.campaign.config import campaign_from_dict
from adversary.campaign.store import ResultStore
from adversary.report.page import make_report
from riskmap.infra.config_mapping import to_plain
from tests.adversary.report.test_report_sections import _record

NAMED = "py:tests.broken_planners:Broken?fault=kmh&name=kmh"
PLANNERS = ["cv", NAMED, f"guard:{NAMED}"]


def _campaign(root):
    config = campaign_from_dict({"name": "names", "planners": PLANNERS,
                                 "scenarios": [{"env": "highway-v0", "episodes": 1}],
                                 "attacks": [{"name": "natural"}]})
    records = [_record(f"job-{i}", planner, "natural", "baseline", planner == NAMED)
               for i, planner in enumerate(PLANNERS)]
    root.mkdir()
    (root / "campaign.json").write_text(json.dumps({"config": to_plain(config),
                                                    "jobs": [r["job_id"] for r in records]}))
    store = ResultStore(root)
    for record in records:
        store.put(record, None)
    store.close()


def test_the_report_names_planners_and_keeps_their_specs(tmp_path):
    _campaign(tmp_path / "c")
    report = make_report(tmp_path / "c")
    results = report["results"]
    named = {r["planner"]: r["planner_name"] for r in results["comparison"]}
    assert named == {"cv": "cv", NAMED: "kmh", f"guard:{NAMED}": "guard-kmh"}
    assert {(g["planner"], g["planner_name"]) for g in results["guard"]} == {(NAMED, "kmh")}
    summary = results["summary_collisions"]["text"]
    assert summary.startswith("kmh fails most: it collided in 1 of its 1 jobs")
    assert "guard-kmh never collided" in summary and "py:" not in summary
    page = (tmp_path / "c" / "report.html").read_text()
    spec = NAMED.replace("&", "&amp;")
    assert f'<td title="{spec}">kmh</td>' in page and f'<td title="guard:{spec}">guard-kmh</td>' in page
    assert f">{spec}" not in page and f">guard:{spec}" not in page    # the SPEC is a cell's title only
    job = (tmp_path / "c" / "jobs" / "job-1.html").read_text()
    assert "<h1>kmh | highway-v0 seed 0 episode 0 | natural</h1>" in job
