"""`adversary scenes` + `adversary attack` end to end with the shipped traffic model."""

import json

import pytest
import torch

from adversary.cli import main
from adversary.crash.attack import AttackConfig
from adversary.crash.run import run_attacks, summarise, table_row
from adversary.crash.selection import SelectionModule
from rasterize.errors import InputError
from riskmap.infra.checkpoint import save_checkpoint

TRAFFIC = "checkpoints/crash_traffic_highway"


@pytest.fixture(scope="module")
def selectors(tmp_path_factory):
    """An untrained ASM pair: the plumbing of `--selector crash`, not its quality."""
    out = tmp_path_factory.mktemp("selectors")
    torch.manual_seed(0)
    for name, mam in (("selector_mam", True), ("selector_no_mam", False)):
        save_checkpoint(out / name, SelectionModule(64), {"mam": mam, "hidden": 64}, kind="crash_selector")
    return out


def test_distance_attack_on_replay_collides_and_resume_recomputes_nothing(scenes, tmp_path):
    out = tmp_path / "attack"
    config = AttackConfig(selector="distance")
    summary = run_attacks("replay", scenes, 1, config, 0, out, TRAFFIC, None, progress=False)
    record = json.loads((out / "attacks" / "scene_00001.json").read_text())
    assert record["status"] == "ok" and record["collision"], record.get("metrics")
    m = record["metrics"]
    assert m["collision_iou"] > 0.02 and m["collision_type"] in ("cut-in", "side-swipe", "ego rear-ends")
    assert record["p"][0] == 0.0 and abs(sum(record["p"]) - 1.0) < 1e-4
    assert record["generation"]["iterations"] < 300          # stopped at the collision
    assert summary["summary"]["collisions"] == 1 and summary["summary"]["scenes"] == 1
    before = (out / "attacks" / "scene_00001.json").stat().st_mtime_ns
    run_attacks("replay", scenes, 1, config, 0, out, TRAFFIC, None, resume=True, progress=False)
    assert (out / "attacks" / "scene_00001.json").stat().st_mtime_ns == before
    with pytest.raises(InputError, match="already holds attacks"):
        run_attacks("replay", scenes, 1, config, 0, out, TRAFFIC, None, progress=False)
    with pytest.raises(InputError, match="other settings"):
        run_attacks("replay", scenes, 1, AttackConfig(selector="random"), 0, out, TRAFFIC, None,
                    resume=True, progress=False)


def test_crash_selector_closed_loop_batch_and_bad_input(scenes, selectors, tmp_path, capsys):
    out = tmp_path / "idm"
    config = AttackConfig(selector="crash", iterations_closed_loop=20, replan_every=10)
    summary = run_attacks("idm", scenes, 2, config, 0, out, TRAFFIC, selectors, progress=False, batch_size=2)
    records = [json.loads(p.read_text()) for p in sorted((out / "attacks").glob("*.json"))]
    assert [r["status"] for r in records] == ["ok", "ok"]
    for r in records:
        assert r["timing"]["rollouts"] >= 2 and r["generation"]["replans"] >= 1
        assert len(r["tracks"]) == r["agents"] - 1
    assert summary["summary"]["scenes"] == 2
    assert main(["attack", "--planner", "idm", "--scenes", str(scenes), "--count", "5",
                 "--out", str(tmp_path / "x"), "--traffic-model", TRAFFIC, "--selector", "distance"]) == 2
    assert "holds 2 scenes, fewer than --count 5" in capsys.readouterr().err
    assert main(["attack", "--planner", "idm", "--scenes", str(scenes), "--count", "1", "--out",
                 str(tmp_path / "y"), "--traffic-model", TRAFFIC, "--selector-model", str(tmp_path / "none")]) == 2
    assert "not found" in capsys.readouterr().err


def test_summary_counts_every_scene_in_the_denominator():
    ok = {"status": "ok", "collision": True, "seconds": 1.0, "timing": {"rollouts": 1},
          "generation": {"iterations": 10, "replans": 0},
          "metrics": {"adversary_off_road": False, "other_off_road": True, "off_road": False,
                      "kinematic_value_mps": 4.0, "solution_found": True, "collision_type": "cut-in"}}
    miss = {"status": "no_candidate", "collision": False, "seconds": 0.5}
    s = summarise([ok, miss])
    assert s["collision_rate"] == 0.5 and s["no_candidate"] == 1 and s["other_off_road_rate"] == 1.0
    assert s["collision_types"] == {"cut-in": 1} and s["solution_rate"] == 1.0
    # a record written before the classification is unknown, never counted
    assert s["failures"]["unknown"] == 1 and s["failures"]["counted"] == 0 and s["failures"]["trials"] == 2
    counted = {**ok, "metrics": {**ok["metrics"], "failure": {
        "fault": "at fault", "avoidable": True, "valid_attack": True, "counts": True}}}
    s = summarise([counted, miss])
    assert s["failures"]["counted"] == 1 and s["failures"]["counted_rate"] == 0.5 and s["failures"]["valid"] == 1
    assert "1/2 (50.0" in table_row("x", s)


def test_replan_hz_reaches_every_drive_and_old_run_json_resumes(scenes, tmp_path, monkeypatch):
    from adversary.crash import judge
    from adversary.crash.attack import replan_hz_of

    seen = []
    real = judge.rollout

    def spy(*args, **kwargs):
        seen.append(kwargs.get("replan_hz"))
        return real(*args, **kwargs)

    monkeypatch.setattr(judge, "rollout", spy)
    config = AttackConfig(selector="distance", iterations_closed_loop=4, replan_every=2, replan_hz=10)
    run_attacks("idm", scenes, 1, config, 0, tmp_path / "fast", TRAFFIC, None, progress=False)
    assert len(seen) >= 2 and set(seen) == {10}            # the first drive, replans, the judged drive
    record = json.loads((tmp_path / "fast" / "attacks" / "scene_00001.json").read_text())
    assert replan_hz_of(record) == 10 and replan_hz_of({"config": {}}) == 2
    assert json.loads((tmp_path / "fast" / "run.json").read_text())["config"]["replan_hz"] == 10
    default = AttackConfig(selector="distance", iterations_closed_loop=4, validity_terms=False)
    run_attacks("idm", scenes, 1, default, 0, tmp_path / "default", TRAFFIC, None, progress=False)
    # A run.json from before the options (no version, neither key) resumes: its reader upgrades it.
    meta = json.loads((tmp_path / "default" / "run.json").read_text())
    del meta["format_version"], meta["config"]["replan_hz"], meta["config"]["validity_terms"]
    (tmp_path / "default" / "run.json").write_text(json.dumps(meta))
    run_attacks("idm", scenes, 1, default, 0, tmp_path / "default", TRAFFIC, None, progress=False, resume=True)
    assert json.loads((tmp_path / "default" / "run.json").read_text())["config"]["replan_hz"] == 2
    with pytest.raises(InputError, match="must divide the 10 Hz"):
        AttackConfig(replan_hz=3)


def test_implausible_plans_are_counted_over_every_drive_and_named_under_the_table(scenes, tmp_path):
    kmh = "py:tests.broken_planners:Broken?fault=kmh&name=kmh"
    config = AttackConfig(selector="distance", iterations_closed_loop=4, replan_every=2)
    summary = run_attacks(kmh, scenes, 1, config, 0, tmp_path / "kmh", TRAFFIC, None,
                          progress=False)["summary"]
    record = json.loads((tmp_path / "kmh" / "attacks" / "scene_00001.json").read_text())
    assert record["implausible_plans"] > 0 and "km/h?" in record["implausible_plan_first"]
    assert summary["implausible_plans"] == record["implausible_plans"]
    assert summary["implausible_plan_episodes"] == 1                  # scenes with any
    assert summary["implausible_plan_first"].startswith("on scene_00001 at ")
    table = (tmp_path / "kmh" / "table.md").read_text()
    assert f"kmh / distance: {record['implausible_plans']} plans in 1 of 1 scenes" in table
    good = run_attacks("cv", scenes, 1, config, 0, tmp_path / "cv", TRAFFIC, None, progress=False)["summary"]
    assert good["implausible_plans"] == 0 and "Implausible" not in (tmp_path / "cv" / "table.md").read_text()
