"""Job pages from hand-made records: a failed job's page shows its error and record, a job whose
artifact is missing or unreadable still gets a page, and the report links to every one."""

import html
import json
import re

from adversary.campaign.config import campaign_from_dict
from adversary.campaign.store import ResultStore
from adversary.report.check import job_pages, site_problems
from adversary.report.page import make_report
from riskmap.infra.config_mapping import to_plain


def _record(job_id, collided, status="ok"):
    record = {"job_id": job_id, "planner": "cv", "env_id": "highway-v0", "scene_seed": 0, "episode": 0,
              "attack": "natural", "attack_name": "natural", "attack_category": "baseline",
              "attack_params": {}, "status": status, "error": None, "timing": {"wall_s": 1.0}}
    if status != "ok":
        return {**record, "error": "RuntimeError: broke on purpose", "traceback": "Traceback ..."}
    return {**record, "collided": collided, "off_road": False, "has_adversary": False,
            "collided_with_adversary": False, "collision_type": "sideswipe" if collided else None,
            "collision_time_s": 1.0 if collided else None, "kinematic_mps": 3.0 if collided else None,
            "adversary_off_road": None, "other_off_road": False, "encounters": 4,
            "dangerous_encounters": 1, "safety_pct": 25.0, "solution_found": True if collided else None,
            "distance_m": 40.0, "attack_extra": {}}


def test_every_job_gets_a_page_even_without_pictures(tmp_path):
    config = campaign_from_dict({"name": "pages", "planners": ["cv"],
                                 "scenarios": [{"env": "highway-v0", "episodes": 3}],
                                 "attacks": [{"name": "natural"}]})
    records = [_record("ok-collided", True), _record("ok-unreadable", False), _record("failed", False, "error")]
    campaign = tmp_path / "c"
    campaign.mkdir()
    (campaign / "campaign.json").write_text(json.dumps(
        {"config": to_plain(config), "jobs": [r["job_id"] for r in records]}))
    store = ResultStore(campaign)
    for r in records:
        store.put(r, b"not an npz" if r["job_id"] == "ok-unreadable" else None)
    store.close()

    report = make_report(campaign, tmp_path / "out")
    out = tmp_path / "out"
    assert sorted(report["pages"]) == sorted(r["job_id"] for r in records)
    assert {p.name for p in job_pages(out / "report.html")} == {f"{r['job_id']}.html" for r in records}
    failed = (out / "jobs" / "failed.html").read_text()
    assert "RuntimeError: broke on purpose" in failed and "The job failed" in failed
    shown = re.search(r'<pre id="record">(.*?)</pre>', failed, re.DOTALL).group(1)
    assert json.loads(html.unescape(shown)) == records[2]
    assert "cannot be read" in (out / "jobs" / "ok-unreadable.html").read_text()
    assert "No artifact was stored" in (out / "jobs" / "ok-collided.html").read_text()
    # a collision without its classification (a record from before it) says so, never guesses
    assert "This collision is not classified" in (out / "jobs" / "ok-collided.html").read_text()
    assert 'id="failure"' not in (out / "jobs" / "ok-unreadable.html").read_text()
    assert 'href="jobs/failed.html"' in (out / "report.html").read_text()     # from the failures table
    assert site_problems(out / "report.html") == []
