"""`adversary evaluate`: stored attack scenes as the third scenario source of `riskmap evaluate`'s
one evaluate (adversary.crash.evaluate_source), driven without an attack."""

import csv
import json
import pickle
import shutil
from pathlib import Path

import pytest

from adversary.crash.evaluate_source import AttackScenario, AttackSceneSource
from adversary.crash.scene_sweep import RecordingSweep, record_scenes
from adversary.crash.scenes import load_record
from rasterize.errors import InputError
from riskmap.evaluation.evaluate import evaluate
from riskmap.sim.records.metrics import path_length_m
from tests.adversary.conftest import exit_code

RECORDING = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad" / "USA_US101-4_1_T-1.xml"
PLANNERS = ("replay", "idm", "cv")
TIMING = ("plan_ms_mean", "plan_ms_p90")       # wall-clock columns: may differ between runs


@pytest.fixture(scope="module")
def evaluated(scenes, tmp_path_factory):
    out = tmp_path_factory.mktemp("evaluate") / "run"
    results = evaluate(AttackSceneSource(scenes), PLANNERS, out, progress=False)
    return out, results


def _rows(out: Path) -> list[dict]:
    with open(out / "episodes.csv", newline="") as f:
        return list(csv.DictReader(f))


def _untimed(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING} for r in rows]


def _log_distance(scenes: Path, name: str, start: int = 0) -> float:
    record = load_record(scenes / f"{name}.npz")
    log = record.log
    return path_length_m(log.states[log.ego_id, start:][log.valid[log.ego_id, start:], :2])


def test_highway_scenes_write_the_common_layout(scenes, evaluated):
    out, results = evaluated
    names = json.loads((scenes / "index.json").read_text())["scenes"]
    assert len(names) == 2
    for f in ("results.json", "episodes.csv", "table.md", "run.json"):
        assert (out / f).is_file(), f
    rows = _rows(out)
    assert [(r["planner"], r["episode"]) for r in rows] == [(p, n) for p in PLANNERS for n in names]
    assert {r["mode"] for r in rows} == {"log"}
    assert results["source"] == "attack_scenes" and results["count"] == 2
    assert results["env_id"] == "highway-v0"
    assert set(results["planners"]) == set(PLANNERS) and results["planners"]["replay"]["episodes"] == 2
    assert json.loads((out / "results.json").read_text())["planners"] == results["planners"]
    for spec in PLANNERS:
        for name in names:
            assert (out / "episodes" / spec / f"{name}.json").is_file()
    table = (out / "table.md").read_text()
    assert table.startswith("2 attack scene(s) of highway-v0") and "no attack" in table
    for spec in PLANNERS:
        assert f"| {spec} | 2 |" in table
    # every collision (the judge's box overlap) is classified; the summary counts the records'
    for row in rows:
        stored = json.loads((out / "episodes" / row["planner"] / f"{row['episode']}.json").read_text())
        assert (stored["failure"] is not None) == stored["collided"] == (row["collided"] == "True")
        assert (stored["collision_time_s"] is not None) == stored["collided"]
        if stored["collided"]:
            assert stored["failure"]["fault"] and stored["collision_iou"] > 0.02
    for spec in PLANNERS:
        mine = [r["collided"] == "True" for r in rows if r["planner"] == spec]
        assert results["planners"][spec]["collided_rate"] == pytest.approx(sum(mine) / len(mine))
    # columns the source does not fill are empty in the CSV and "–" in the table
    assert all(r["red_light_violations"] == "" for r in rows)
    assert all(r["jerk_mps3"] != "" and r["human_distance_m"] != "" for r in rows)


def test_replay_reproduces_the_recorded_human(scenes, evaluated):
    out, _ = evaluated
    for row in _rows(out):
        if row["planner"] != "replay":
            continue
        assert row["collided"] == "False" and row["off_road"] == "False"    # the log has no collision
        logged = _log_distance(scenes, row["episode"])
        assert float(row["distance_m"]) == pytest.approx(logged, rel=1e-3, abs=0.05)
        assert float(row["human_distance_m"]) == pytest.approx(logged, rel=1e-9)
        assert float(row["ade_m"]) < 0.05 and float(row["goal_error_m"]) < 0.05
        record = json.loads((out / "episodes" / "replay" / f"{row['episode']}.json").read_text())
        assert record["handover_s"] == 0.0 and record["simulated_s"] == pytest.approx(8.0)
        assert record["failure"] is None and record["collision_time_s"] is None


def test_resume_redoes_only_the_deleted_episode(scenes, evaluated, tmp_path, monkeypatch):
    done, _ = evaluated
    out = tmp_path / "run"
    shutil.copytree(done, out)
    records = sorted((out / "episodes").rglob("*.json"))
    assert len(records) == 6
    gone = out / "episodes" / "idm" / "scene_00001.json"
    before = json.loads(gone.read_text())
    stamps = {p: p.stat().st_mtime_ns for p in records if p != gone}
    gone.unlink()
    drives = []
    original = AttackScenario.drive

    def counted(self, spec, run_out):
        drives.append((spec, self.id))
        return original(self, spec, run_out)

    monkeypatch.setattr(AttackScenario, "drive", counted)
    source = AttackSceneSource(str(scenes))
    with pytest.raises(InputError, match="--resume"):        # a finished run is not overwritten
        evaluate(source, PLANNERS, out, progress=False)
    with pytest.raises(InputError, match="only --count and --planners may change"):
        evaluate(AttackSceneSource(str(scenes), seed=3), PLANNERS, out, resume=True, progress=False)
    evaluate(source, PLANNERS, out, resume=True, progress=False)
    assert drives == [("idm", "scene_00001")]
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    after = json.loads(gone.read_text())
    for key in ("rollout_s", *TIMING):
        before.pop(key, None), after.pop(key, None)
    assert after == before
    assert _untimed(_rows(out)) == _untimed(_rows(done))


def test_command_prints_the_table_and_resumes(scenes, tmp_path, capsys):
    out = tmp_path / "cli"
    argv = ["evaluate", "--scenes", str(scenes), "--planners", "replay,idm", "--count", "1",
            "--out", str(out), "--quiet"]
    assert exit_code(argv) == 0
    printed = capsys.readouterr().out
    assert printed == (out / "table.md").read_text()
    assert printed.startswith("1 attack scene(s) of highway-v0") and "| replay | 1 |" in printed
    # more scenes on --resume: only the new ones are driven
    assert exit_code([*argv[:5], "--count", "2", "--out", str(out), "--quiet", "--resume"]) == 0
    assert "| idm | 2 |" in capsys.readouterr().out
    assert len(_rows(out)) == 4


def test_recorded_scene_directory(tmp_path):
    scenes = tmp_path / "scenes"
    record_scenes(RecordingSweep((str(RECORDING),)), 1, scenes, progress=False)
    [name] = json.loads((scenes / "index.json").read_text())["scenes"]
    record = load_record(scenes / f"{name}.npz")
    source = AttackSceneSource(scenes)
    assert source.recorded and source.route_rule == "the route rule"
    pickle.loads(pickle.dumps(source.scenarios()[0]))        # workers get scenarios pickled
    results = evaluate(source, ("replay", "idm"), tmp_path / "out", progress=False)
    assert results["family"] == "us101" and results["env_id"] == "commonroad"
    replay, idm = _rows(tmp_path / "out")
    assert replay["collided"] == "False" and float(replay["ade_m"]) == pytest.approx(0.0, abs=1e-9)
    # measured from the handover at t0: the human's distance from there on
    end = record.t0_step + record.stride * record.scene.future_steps + 1
    log = record.log
    logged = path_length_m(log.states[log.ego_id, record.t0_step:end, :2])
    assert float(replay["distance_m"]) == pytest.approx(logged, rel=1e-9)
    assert float(replay["human_distance_m"]) == pytest.approx(logged, rel=1e-9)
    stored = json.loads((tmp_path / "out" / "episodes" / "idm" / f"{name}.json").read_text())
    assert stored["handover_s"] == pytest.approx(record.scene.t0_s)
    assert stored["driver"] == "RecordedRouteIdmPlanner" and idm["label"] == "IDM"
    assert (tmp_path / "out" / "table.md").read_text().startswith("1 attack scene(s) of us101 recordings")


@pytest.mark.parametrize("case, expected", [
    ("no-index", "holds no readable scene index"),
    ("count-too-many", "--count 5"),
    ("planner-nosuch", "nosuch"),
])
def test_bad_input_is_one_line_before_anything_is_written(case, expected, scenes, tmp_path, capsys):
    out = tmp_path / "out"
    scenes_arg = str(tmp_path) if case == "no-index" else str(scenes)
    planners = "nosuch" if case == "planner-nosuch" else "replay"
    count = ["--count", "5"] if case == "count-too-many" else []
    code = exit_code(["evaluate", "--scenes", scenes_arg, "--planners", planners, *count, "--out", str(out),
                      "--quiet"])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and err[0].startswith("adversary evaluate: error:"), err
    assert expected in err[0] and not out.exists()
