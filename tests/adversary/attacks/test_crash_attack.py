"""The crash attack in a campaign: params validated when the config is read, a tiny CRASH job
gives a complete and reproducible record, and the report's CRASH ablation has its rows."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from adversary.attacks.crash import SELECTORS
from adversary.campaign.config import campaign_from_dict
from adversary.campaign.job import run_job
from adversary.campaign.run import RunOptions, run_campaign
from adversary.campaign.store import ResultStore
from adversary.report.check import report_problems
from adversary.report.frames import load_artifact, recorded_indices
from adversary.report.page import make_report
from rasterize.errors import InputError


@pytest.fixture(scope="module")
def selector_dir(tmp_path_factory) -> Path:
    """Untrained selectors of the shipped traffic model's width (only their shape matters here)."""
    from adversary.crash.selection import SelectionModule
    from adversary.crash.train_selector import CHECKPOINT_KIND
    from adversary.crash.train_traffic import CHECKPOINT_KIND as TRAFFIC_KIND
    from riskmap.infra.checkpoint import read_sidecar, save_checkpoint

    hidden = read_sidecar(Path("checkpoints/crash_traffic_highway"), kind=TRAFFIC_KIND)["model"]["hidden"]
    out = tmp_path_factory.mktemp("selectors")
    torch.manual_seed(0)
    for name, mam in (("selector_mam", True), ("selector_no_mam", False)):
        save_checkpoint(out / name, SelectionModule(hidden), {"mam": mam, "hidden": hidden}, kind=CHECKPOINT_KIND)
    return out


def _config(selector_dir: Path, **changes) -> dict:
    return {"name": "crash", "seed": 0, "planners": ["idm"],
            "scenarios": [{"env": "highway-v0", "seed": 0, "episodes": 1}],
            "attacks": [{"name": "crash", "label": "MAM+ASM",
                         "params": {"selector": "crash", "iterations": 12, "replan_every": 5,
                                    "selector_model": str(selector_dir)}},
                        {"name": "crash", "label": "DS", "params": {"selector": "distance", "iterations": 12,
                                                                    "replan_every": 5}}],
            "report": {"gallery": 2}, **changes}


@pytest.fixture(scope="module")
def crash_campaign(selector_dir, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("crash_campaign") / "c"
    run_campaign(campaign_from_dict(_config(selector_dir)), out, RunOptions(progress=False))
    return out


def test_selectors_are_crash_own():
    from adversary.crash.selection import SELECTORS as CRASH_SELECTORS

    assert SELECTORS == CRASH_SELECTORS


@pytest.mark.parametrize("params, fix", [
    ({"selector": "strive"}, "use one of crash, crash-no-mam, distance"),
    ({"replan_every": 0}, "replan_every must be >= 1"),
    ({"iterations": -1}, "iterations must be >= 0"),
    ({"t0_s": 1.0}, "use a multiple of 0.5 s that is >= 2.0"),
    ({"traffic_model": "runs/{env}"}, "the only placeholder allowed is {family}"),
])
def test_bad_params_are_one_line_errors_naming_the_fix(selector_dir, params, fix):
    config = _config(selector_dir, attacks=[{"name": "crash", "params": params}])
    with pytest.raises(InputError) as error:
        campaign_from_dict(config)
    assert fix in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize("params, fix", [
    ({"traffic_model": "runs/nothing_{family}", "selector": "distance"}, "train one with `adversary train-traffic`"),
    ({"selector_model": "runs/nothing"}, "train selectors with `adversary train-selector`"),
])
def test_missing_models_stop_the_campaign_before_any_job(selector_dir, tmp_path, params, fix):
    config = campaign_from_dict(_config(selector_dir, attacks=[{"name": "crash", "params": params}]))
    with pytest.raises(InputError) as error:
        run_campaign(config, tmp_path / "c", RunOptions(progress=False))
    assert fix in str(error.value) and "\n" not in str(error.value)
    assert not (tmp_path / "c" / "campaign.json").exists()


def test_a_selector_model_is_only_needed_by_learned_selectors(selector_dir):
    config = campaign_from_dict(_config(selector_dir, attacks=[
        {"name": "crash", "params": {"selector": "nearest", "selector_model": "runs/nothing"}}]))
    assert config.jobs()[0].attack_params.paths("intersection-v0") == (
        Path("checkpoints/crash_traffic_intersection"), None)


def test_a_crash_job_record_has_the_campaign_fields_and_the_attack(crash_campaign):
    store = ResultStore(crash_campaign)
    records = {r["attack"]: r for r in store.records()}
    store.close()
    assert set(records) == {"MAM+ASM", "DS"}
    for label, r in records.items():
        assert r["status"] == "ok" and r["attack_category"] == "selection", r.get("error")
        assert r["attacked"] is True and r["has_adversary"] is True
        extra = r["attack_extra"]
        assert extra["selector"] == {"MAM+ASM": "crash", "DS": "distance"}[label]
        assert extra["iterations"] <= 12 and extra["replans"] >= 1
        p = extra["p"]
        assert p[0] == 0.0 and abs(sum(p) - 1.0) < 1e-3 and p[extra["adversary_row"]] == max(p)
        assert isinstance(r["collided"], bool) and r["collided_with_adversary"] <= r["collided"]
        assert (r["kinematic_mps"] is not None) == r["collided_with_adversary"]
        assert r["distance_m"] > 10.0 and r["simulated_s"] == 8.0 and r["safety_pct"] is None
        assert r["timing"]["wall_s"] > 0 and r["timing"]["attack_seconds"] > 0
        with np.load(crash_campaign / "artifacts" / f"{r['job_id']}.npz") as data:
            assert data["crash_panel_png"][:4].tobytes() == b"\x89PNG"
        # The final drive is kept as the episode attacks keep theirs: the report animates it.
        art = load_artifact(crash_campaign / "artifacts" / f"{r['job_id']}.npz")
        assert art.has_frames and len(recorded_indices(art.final)) >= 70   # 8 s at 10 Hz
        assert art.final.dt == pytest.approx(0.1) and art.final.lanes


def _without_timing(record: dict) -> dict:
    return {k: v for k, v in record.items() if k != "timing"}


def test_a_crash_job_reruns_to_the_same_record(crash_campaign, selector_dir):
    """Rerun in this process, after other jobs: identical apart from the timings."""
    store = ResultStore(crash_campaign)
    stored = {r["job_id"]: r for r in store.records()}
    store.close()
    jobs = campaign_from_dict(_config(selector_dir)).jobs()
    for job in reversed(jobs):
        again = json.loads(json.dumps(run_job(job)["record"]))
        assert _without_timing(again) == _without_timing(stored[job.job_id])


def test_a_scene_that_cannot_be_attacked_is_an_ok_record_counted_in_the_ablation(
        crash_campaign, selector_dir, monkeypatch, tmp_path):
    from adversary.crash.highway_source import HighwaySource

    def human_crashed(*args, **kwargs):
        raise InputError("highway-v0 seed 0 episode 0: the human crashed at 3.1 s, before t0 + horizon")

    monkeypatch.setattr(HighwaySource, "record", human_crashed)
    [job] = [j for j in campaign_from_dict(_config(selector_dir)).jobs() if j.attack == "DS"]
    record = run_job(job)["record"]
    assert record["status"] == "ok" and record["attacked"] is False and record["collided"] is False
    assert "the human crashed" in record["not_attacked"] and record["has_adversary"] is False

    # the report counts it beside the attacked job of the same (attack, planner)
    out = tmp_path / "c"
    out.mkdir()
    meta = json.loads((crash_campaign / "campaign.json").read_text())
    record = {**record, "job_id": record["job_id"] + "-copy"}
    meta["jobs"].append(record["job_id"])
    (out / "campaign.json").write_text(json.dumps(meta))
    source = ResultStore(crash_campaign)
    store = ResultStore(out)
    for r in source.records() + [record]:
        store.put(r, None)
    store.close()
    source.close()
    rows = {row["attack"]: row for row in make_report(out)["results"]["crash_ablation"]}
    assert rows["DS"]["jobs"] == 2 and rows["DS"]["not_attacked"] == 1
    assert rows["DS"]["adversary_collision_rate"]["n"] == 2
    assert rows["MAM+ASM"]["not_attacked"] == 0


def test_the_report_has_a_crash_ablation_row_per_label_and_planner(crash_campaign, tmp_path):
    report = make_report(crash_campaign, tmp_path / "report")
    rows = report["results"]["crash_ablation"]
    assert [(r["attack"], r["planner"]) for r in rows] == [("DS", "idm"), ("MAM+ASM", "idm")]
    assert all(r["jobs"] == 1 and r["adversary_collision_rate"]["n"] == 1 for r in rows)
    assert [t["attack"] for t in report["timing"]["crash_ablation"]] == ["DS", "MAM+ASM"]
    html = (tmp_path / "report" / "report.html").read_text()
    assert 'id="crash-ablation"' in html and "MAM+ASM" in html
    assert report_problems(tmp_path / "report" / "report.html") == []
    assert len(report["results"]["gallery_images"]) == 2
