"""`riskmap evaluate --commonroad`: planners drive the recorded vehicles of the fixtures."""

import json
from pathlib import Path

import pytest

import riskmap.sim.worlds.commonroad_replay as replay_module
from rasterize.errors import InputError
from riskmap.cli import main
from riskmap.evaluation.evaluate import evaluate
from riskmap.evaluation.sources import RecordingSource

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"
pytestmark = pytest.mark.slow


def evaluate_commonroad(recordings, planners, out, resume=False, progress=True, workers=1, **source):
    """`riskmap evaluate --commonroad`: the one evaluate on a recordings source; {SPEC: summary}."""
    return evaluate(RecordingSource(tuple(map(str, recordings)), **source), planners, out, workers=workers,
                    resume=resume, progress=progress)["planners"]


def test_replay_recovers_the_human_and_a_rerun_resumes(tmp_path, monkeypatch):
    out = tmp_path / "cr"
    results = evaluate_commonroad([FIXTURES], ("replay",), out, progress=False)
    replay = results["replay"]
    assert replay["episodes"] == len(list((out / "episodes" / "replay").glob("*.json"))) > 0
    assert replay["ade_m"]["mean"] < 2.0             # the controller tracking the log itself
    assert 0.0 <= replay["safety_pct"]["mean"] <= 100.0
    assert all(r["encounters"] > 0 for r in map(lambda p: json.loads(p.read_text()),
                                                 (out / "episodes" / "replay").glob("*.json")))
    assert json.loads((out / "results.json").read_text())["results"]["replay"] == replay
    assert "| replay |" in (out / "table.md").read_text()

    def must_not_drive(*args, **kwargs):
        raise AssertionError("a finished episode was driven again")

    original = replay_module.replay_commonroad_episode
    monkeypatch.setattr(replay_module, "replay_commonroad_episode", must_not_drive)
    assert evaluate_commonroad([FIXTURES], ("replay",), out, resume=True, progress=False) == results
    with pytest.raises(InputError, match="--resume"):
        evaluate_commonroad([FIXTURES], ("replay",), out, progress=False)
    with pytest.raises(InputError, match="other settings"):
        evaluate_commonroad([FIXTURES], ("replay",), out, resume=True, progress=False, goal="human")
    # Resuming with one more planner drives only its episodes; the replay records are kept.
    monkeypatch.setattr(replay_module, "replay_commonroad_episode", original)
    with_cv = evaluate_commonroad([FIXTURES], ("replay", "cv"), out, resume=True, progress=False)
    assert with_cv["replay"] == replay and with_cv["cv"]["episodes"] == replay["episodes"]


def test_cli_refuses_mixing_recordings_with_simulated_settings(tmp_path, capsys):
    assert main(["evaluate", "--commonroad", str(FIXTURES), "--planners", "cv", "--env",
                 "highway-v0", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--commonroad" in err and "\n" not in err


def test_workers_give_the_same_records_and_bad_input_leaves_nothing(tmp_path):
    one = evaluate_commonroad([FIXTURES], ("replay", "cv"), tmp_path / "one", progress=False)
    two = evaluate_commonroad([FIXTURES], ("replay", "cv"), tmp_path / "two", progress=False, workers=2)
    strip = lambda s: {k: v for k, v in s.items() if not k.startswith("plan_ms")}  # noqa: E731
    assert {k: strip(v) for k, v in one.items()} == {k: strip(v) for k, v in two.items()}
    for spec in ("replay", "cv"):
        # every collision classified: the fault classes add up to the collisions, none unknown
        s = one[spec]
        assert s["at_fault"] + s["struck_from_behind"] + s["side"] == round(s["collision_rate"] * s["episodes"])
        assert s["unknown"] == 0 and s["counted"] <= s["at_fault"] and s["counted"] <= s["avoidable"]
    never = tmp_path / "never"
    with pytest.raises(InputError, match="unknown planner spec"):
        evaluate_commonroad([FIXTURES], ("replay", "nope:x"), never, progress=False)
    assert not never.exists()


@pytest.mark.parametrize("option", [["--goal", "human"], ["--goal-variance", "0.5"]])
def test_goal_is_for_recordings_only(tmp_path, capsys, option):
    assert main(["evaluate", "--planners", "cv", "--env", "highway-v0", "--episodes", "1", *option,
                 "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--goal and --goal-variance are for recordings" in err and "\n" not in err
    assert not (tmp_path / "x").exists()


def test_cli_runs_recordings_in_reactive_mode(tmp_path, capsys):
    out = tmp_path / "reactive"
    assert main(["evaluate", "--commonroad", str(FIXTURES / "USA_US101-4_1_T-1.xml"), "--planners",
                 "cv", "--mode", "reactive", "--quiet", "--out", str(out)]) == 0
    assert "| cv |" in capsys.readouterr().out
    assert json.loads((out / "run.json").read_text())["mode"] == "reactive"
    assert json.loads((out / "results.json").read_text())["mode"] == "reactive"
    with pytest.raises(InputError, match="--mode 'x'"):
        evaluate_commonroad([FIXTURES], ("cv",), tmp_path / "x", progress=False, mode="x")
    assert not (tmp_path / "x").exists()


def test_red_light_violations_are_summed_beside_collisions_with_the_human_reference():
    from riskmap.evaluation.evaluate import markdown_table, summarise

    source = RecordingSource((str(FIXTURES),))

    def record(violations, human, **kw):
        base = {"planner": "cv", "collided": False, "off_road": False, "failure": None, "safety_pct": 0.0,
                "dangerous": 0, "encounters": 1, "ade_m": 1.0, "goal_error_m": 1.0, "distance_m": 10.0,
                "human_distance_m": 10.0, "min_gap_m": 5.0, "mean_speed_mps": 10.0,
                "red_light_violations": violations, "human_red_light_violations": human}
        return {**base, **kw}

    summary = summarise(source, ("cv",), [record(2, 1), record(0, 1), record(1, 0)])["cv"]
    assert (summary["red_light_violations"], summary["human_red_light_violations"],
            summary["red_light_violation_episodes"]) == (3, 2, 2)
    assert "| 3 (2) |" in markdown_table(source, {"cv": summary})
    old = record(0, 0)
    del old["red_light_violations"], old["human_red_light_violations"]   # written before the count
    summary = summarise(source, ("cv",), [record(1, 1), old])["cv"]
    assert summary["red_light_violations"] is None and "| n/a (n/a) |" in markdown_table(source, {"cv": summary})
    # rows by display name: checkpoints by stem (told apart), a py: plug-in by its name=
    specs = ("riskmap:a/best", "riskmap:b/best", "py:riskmap_example_planner:GapKeeper?headway_s=2&name=gk2")
    table = markdown_table(source, summarise(source, specs, [{**record(0, 0), "planner": spec}
                                                               for spec in specs for _ in range(2)]))
    assert "| best | 2 |" in table and "| best-2 | 2 |" in table and "| gk2 | 2 |" in table
    assert "riskmap:" not in table and "py:" not in table


def test_replan_hz_reaches_every_recorded_episode(tmp_path):
    calls = {}
    for hz in (2, 10):
        evaluate_commonroad([FIXTURES], ("cv",), tmp_path / str(hz), progress=False, replan_hz=hz)
        calls[hz] = {p.name: json.loads(p.read_text())["plan_calls"]
                     for p in (tmp_path / str(hz) / "episodes" / "cv").glob("*.json")}
    assert calls[2] and calls[2].keys() == calls[10].keys()
    assert all(calls[10][name] >= 4 * calls[2][name] > 0 for name in calls[2])
    assert "replan_hz" not in json.loads((tmp_path / "2" / "run.json").read_text())   # old runs resume
    assert json.loads((tmp_path / "10" / "run.json").read_text())["replan_hz"] == 10
    with pytest.raises(InputError, match="--replan-hz 4: must divide"):
        evaluate_commonroad([FIXTURES], ("cv",), tmp_path / "bad", progress=False, replan_hz=4)


def test_max_episodes_evaluates_a_seeded_choice_of_recorded_vehicles(tmp_path, capsys):
    def chosen(out, seed):
        assert main(["evaluate", "--commonroad", str(FIXTURES), "--planners", "replay",
                     "--max-episodes", "2", "--seed", str(seed), "--out", str(out), "--quiet"]) == 0
        assert json.loads((out / "results.json").read_text())["max_episodes"] == 2
        return sorted(p.name for p in (out / "episodes" / "replay").glob("*.json"))

    first = chosen(tmp_path / "a", 0)
    assert len(first) == 2 and chosen(tmp_path / "b", 0) == first
    assert main(["evaluate", "--commonroad", str(FIXTURES), "--planners", "replay", "--episodes",
                 "2", "--out", str(tmp_path / "bad")]) == 2
    assert "--max-episodes" in capsys.readouterr().err


def test_implausible_plans_on_recordings_are_summed_and_named_under_the_table(tmp_path):
    kmh = "py:tests.broken_planners:Broken?fault=kmh&name=kmh"
    out = tmp_path / "cr"
    results = evaluate_commonroad([FIXTURES], ("cv", kmh), out, progress=False, limit=1)
    assert results[kmh]["implausible_plans"] > 0 and results[kmh]["implausible_plan_episodes"] == 1
    first = results[kmh]["implausible_plan_first"]
    assert "km/h?" in first and " vehicle " in first                 # where it first happened
    assert results["cv"]["implausible_plans"] == 0 and results["cv"]["implausible_plan_first"] is None
    table = (out / "table.md").read_text()
    assert f"kmh: {results[kmh]['implausible_plans']} plans in 1 of 1 episodes" in table
    assert "cv:" not in table
