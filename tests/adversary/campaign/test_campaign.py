"""A tiny campaign end to end: store, resume after an interruption, failures, report."""

import json

import pytest

from adversary.attacks.registry import NaturalParams, register_attack
from adversary.campaign.run import RunOptions, run_campaign
from adversary.campaign.store import ResultStore
from adversary.cli import main
from adversary.report.check import page_summary, report_problems
from adversary.report.page import make_report
from rasterize.errors import InputError
from tests.adversary.conftest import TINY, tiny_config

pytestmark = pytest.mark.slow


def _results(campaign_dir, tmp_path, name):
    report = make_report(campaign_dir, tmp_path / name)
    return report["results"]


def test_every_job_has_one_record_with_the_fields_of_the_brief(tiny_campaign):
    store = ResultStore(tiny_campaign)
    records = store.records()
    store.close()
    assert len(records) == 12 and all(r["status"] == "ok" for r in records)
    for r in records:
        for key in ("collided", "collided_with_adversary", "adversary_off_road", "other_off_road",
                    "kinematic_mps", "solution_found", "safety_pct", "distance_m", "error"):
            assert key in r
        assert 0.0 <= r["safety_pct"] <= 100.0
        assert r["has_adversary"] == (r["attack"] != "natural")
        assert (r["kinematic_mps"] is not None) == r["collided"]
        assert (r["solution_found"] is not None) == r["collided"]
        # every collision classified (riskmap.sim.records.failures), the adversary's as an attack
        assert (r["failure"] is not None) == r["collided"]
        if r["collided"]:
            assert r["failure"]["fault"] in ("at fault", "struck from behind", "side")
            assert ("valid_attack" in r["failure"]) == r["collided_with_adversary"]
        assert (tiny_campaign / "artifacts" / f"{r['job_id']}.npz").is_file()
    natural_cv = [r for r in records if r["planner"] == "cv" and r["attack"] == "natural"]
    # cv keeps the speed and heading: 3 s of progress at its start speed, on a straight road.
    assert all(r["distance_m"] > 30 for r in natural_cv)


def test_interrupted_and_resumed_campaign_gives_the_same_report(tiny_campaign, tmp_path):
    out = tmp_path / "split"
    first = run_campaign(tiny_config(), out, RunOptions(max_jobs=3, progress=False))
    assert first["finished"] == 3
    # A write that was cut off mid-way leaves only a temp file: it must not count as finished.
    (out / "records" / ".half-written.json.tmp").write_text("{")
    with pytest.raises(InputError, match="--resume"):
        run_campaign(tiny_config(), out, RunOptions(progress=False))
    second = run_campaign(tiny_config(), out, RunOptions(resume=True, progress=False))
    assert second["ran"] == 9 and second["finished"] == 12
    again = run_campaign(tiny_config(), out, RunOptions(resume=True, progress=False))
    assert again["ran"] == 0                        # nothing runs twice
    assert len(list((out / "records").glob("*.json"))) == 12
    assert _results(out, tmp_path, "split_report") == _results(tiny_campaign, tmp_path, "full_report")


def test_resume_refuses_another_config(tiny_campaign):
    other = tiny_config(budget={"episode_s": 2.0})
    with pytest.raises(InputError, match="another config"):
        run_campaign(other, tiny_campaign, RunOptions(resume=True, progress=False))


class _Exploding:
    adversary = None

    def start(self, run):
        raise RuntimeError("attack broke on purpose")

    def step(self, run):
        pass


def test_a_failing_job_is_recorded_and_the_campaign_goes_on(tmp_path):
    register_attack("test_exploding", NaturalParams, lambda params, seed: _Exploding(), "rule",
                    "raises on start (test only)")
    config = tiny_config(planners=["cv"], scenarios=[{"env": "highway-v0", "episodes": 1}],
                         attacks=[{"name": "test_exploding"}, {"name": "natural"}],
                         budget={"episode_s": 1.0})
    counts = run_campaign(config, tmp_path / "c", RunOptions(progress=False))
    assert counts == {"total": 2, "finished": 2, "ran": 2, "failed": 1, "collided": 0}
    store = ResultStore(tmp_path / "c")
    failed = [r for r in store.records() if r["status"] == "error"]
    store.close()
    assert failed[0]["error"] == "RuntimeError: attack broke on purpose"
    results = _results(tmp_path / "c", tmp_path, "report")
    assert results["failures"][0]["error"] == "RuntimeError: attack broke on purpose"


def test_report_page_has_every_image_and_only_filled_tables(tiny_campaign, tmp_path):
    make_report(tiny_campaign, tmp_path / "report")
    page = tmp_path / "report" / "report.html"
    assert report_problems(page) == []
    summary = page_summary(page)
    ids = {t["id"] for t in summary["tables"]}
    assert {"comparison", "by-family", "timing", "versions"} <= ids
    assert len(summary["images"]) >= 1 + 2 * 2          # metrics + gallery panels and strips
    text = page.read_text()
    assert text.count("Not run in this campaign") == 2    # CRASH ablation, guard
    search_rows = next(t["rows"] for t in summary["tables"] if t["id"] == "search")
    assert search_rows == len(TINY["planners"])          # one row per (search attack, planner)
    assert "figures/search.png" in summary["images"]
    saved = json.loads((tmp_path / "report" / "report.json").read_text())
    rows = saved["results"]["comparison"]
    assert {(r["planner"], r["attack"]) for r in rows} == {
        (p, a) for p in TINY["planners"] for a in ("natural", "aggressive_neighbour", "nsga2_search")}
    for row in rows:
        rate = row["collision_rate"]
        assert rate["lo"] <= rate["value"] <= rate["hi"] and rate["n"] == 2
    history = saved["results"]["search_history"]             # one per search job (2 planners x 2 scenes)
    assert len(history) == 4 and all(len(h["generations"]) == 2 and h["pareto_front"] for h in history)


def test_cli_prints_one_line_errors(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nplanners: [cv]\nscenarios: [{env: highway-v0}]\nattacks: [{name: nope}]\n")
    assert main(["stress-test", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("adversary stress-test: error: unknown attack 'nope'") and "\n" not in err
    assert main(["report", str(tmp_path / "nothing")]) == 2


def test_job_results_do_not_depend_on_what_ran_before_in_the_process():
    from adversary.campaign.job import run_job

    config = tiny_config(planners=["idm"], scenarios=[{"env": "highway-v0", "episodes": 1},
                                                      {"env": "intersection-v0", "episodes": 1}],
                         attacks=[{"name": "natural"}], budget={"episode_s": 2.0})
    highway, intersection = config.jobs()
    first = run_job(highway)["record"]
    run_job(intersection)             # highway-env's intersection env edits IDMVehicle's class
    again = run_job(highway)["record"]
    first.pop("timing"), again.pop("timing")
    assert first == again
