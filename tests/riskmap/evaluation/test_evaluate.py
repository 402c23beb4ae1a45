import json

import numpy as np
import pytest

import riskmap.evaluation.evaluate as evaluate_module
from rasterize.errors import InputError
from riskmap.cli import main
from riskmap.evaluation.evaluate import evaluate
from riskmap.evaluation.sources import EnvSource
from riskmap.sim.worlds.episode import make_env
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode
from riskmap.sim.worlds.log_replay import HumanLog, LogReplayEpisode, ReplayPlanner, record_human_episode

ENV = "intersection-v0"


@pytest.fixture(scope="module")
def human_log():
    return record_human_episode(make_env(ENV), ENV, seed=11, episode=0, rate_hz=10, episode_s=3.0)


def _drive_in_log(planner, log, replay_ego):
    env = make_env(ENV)
    run = LogReplayEpisode(env, ENV, 11, 0, log, 10, replay_ego=replay_ego)
    drive_episode(env, planner, DriveConfig(ENV, 1, seed=11, episode_s=3.0), 0, run=run)
    tracks = run.recorder.tracks()
    return run, tracks.states[: tracks.num_agents], tracks.valid[: tracks.num_agents]


@pytest.mark.slow
def test_log_mode_replay_reproduces_the_human(human_log):
    planner = ReplayPlanner()
    planner.set_log(human_log)
    run, states, valid = _drive_in_log(planner, human_log, replay_ego=True)
    assert run.steps == human_log.num_steps - 1 == 30
    ego = states[run.recorder.ego_id][valid[run.recorder.ego_id]]
    np.testing.assert_allclose(ego[:, :2], human_log.ego_xy(), atol=1e-9)
    _assert_ados_follow_the_record(human_log, states, valid, run.recorder.ego_id)


def _assert_ados_follow_the_record(log, states, valid, ego_id):
    """Every recorded ado position appears in the replayed run at the same step (synchronised)."""
    for a in range(log.states.shape[0]):
        if a == log.ego_id:
            continue
        for k in np.flatnonzero(log.valid[a]):
            others = valid[:, k].copy()
            others[ego_id] = False
            distance = np.linalg.norm(states[others, k, :2] - log.states[a, k, :2], axis=1)
            assert distance.min() < 1e-9


@pytest.mark.slow
def test_log_mode_traffic_ignores_the_ego(human_log):
    # A constant-velocity ego drives differently from the human; the traffic still replays its
    # record exactly (it does not react), which is what log mode means.
    from riskmap.planner.baselines import ConstantVelocityPlanner

    run, states, valid = _drive_in_log(ConstantVelocityPlanner(), human_log, replay_ego=False)
    ego = states[run.recorder.ego_id][valid[run.recorder.ego_id]]
    assert np.abs(ego[:, :2] - human_log.ego_xy()[: len(ego)]).max() > 0.1
    _assert_ados_follow_the_record(human_log, states, valid, run.recorder.ego_id)


def test_replay_needs_a_log_and_log_mode():
    from tests.scenes import constant_velocity_scene

    with pytest.raises(InputError, match="--mode log"):
        ReplayPlanner().plan(constant_velocity_scene())
    with pytest.raises(InputError, match="--mode log only"):
        EnvSource(ENV, 1, mode="reactive").check(("idm", "replay"))
    with pytest.raises(InputError, match="once"):
        evaluate(EnvSource(ENV, 1), ("cv", "cv"), "never-written")


@pytest.mark.slow
def test_evaluate_writes_tables_and_resumes_without_recomputing(tmp_path, monkeypatch):
    out = tmp_path / "ev"
    args = ["evaluate", "--planners", "idm,replay", "--env", ENV, "--episodes", "2", "--seed", "11",
            "--episode-s", "2", "--out", str(out), "--quiet"]
    assert main(args) == 0
    results = json.loads((out / "results.json").read_text())["planners"]
    for spec in ("idm", "replay"):
        assert results[spec]["episodes"] == 2
        assert results[spec]["ade_m"]["mean"] == 0.0 and results[spec]["goal_error_m"]["mean"] == 0.0
    assert results["replay"]["safety_pct"] == results["idm"]["safety_pct"]
    rows = (out / "episodes.csv").read_text().splitlines()
    assert len(rows) == 1 + 4 and rows[0].startswith("planner,name,label,episode")
    assert "| idm | 2 |" in (out / "table.md").read_text()
    assert main(args) == 2                                  # refuses to overwrite without --resume

    # Resuming finished work recomputes nothing; adding a planner computes only that planner.
    calls = []
    real = evaluate_module.drive_task

    def counting(scenario, spec, out_dir):
        calls.append((spec, scenario.episode))
        return real(scenario, spec, out_dir)

    monkeypatch.setattr(evaluate_module, "drive_task", counting)
    monkeypatch.setattr(evaluate_module, "prepare_task", lambda *a: pytest.fail("re-recorded"))
    source = EnvSource(ENV, 2, seed=11, episode_s=2.0)
    again = evaluate(source, ("idm", "replay"), out, resume=True, progress=False)["planners"]
    assert calls == [] and again == results
    evaluate(source, ("idm", "replay", "cv"), out, resume=True, progress=False)
    assert calls == [("cv", 0), ("cv", 1)]
    with pytest.raises(InputError, match="other settings"):
        evaluate(EnvSource(ENV, 2, seed=12, episode_s=2.0), ("idm",), out, resume=True, progress=False)
    log = HumanLog.load(out / "logs" / "episode_000000.npz")
    assert log.num_steps == 21 and log.dt_s == pytest.approx(0.1)


@pytest.mark.slow
def test_log_replay_keeps_agent_ids():
    """Every replayed vehicle is recorded under an id whose log agent the replay knows by
    construction; its recorded states equal the log's (nothing is matched by position)."""
    from riskmap.registry import make_planner

    env = make_env("highway-v0", 10)
    log = record_human_episode(env, "highway-v0", 3, 0, 10, 4.0)
    run = LogReplayEpisode(env, "highway-v0", 3, 0, log, 10)
    drive_episode(env, make_planner("cv"), DriveConfig("highway-v0", 1, seed=3, episode_s=3.0), 0, run=run)
    tracks = run.recorder.tracks()
    states, valid = tracks.states, tracks.valid
    ids = run.log_ids()
    assert ids[run.recorder.ego_id] == log.ego_id
    replayed = [a for a in range(len(ids)) if ids[a] >= 0 and a != run.recorder.ego_id]
    assert len(replayed) > 5
    for agent in replayed:
        steps = np.flatnonzero(valid[agent])
        np.testing.assert_allclose(states[agent, steps, :2], log.states[ids[agent], steps, :2], atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("hz", [2, 10])
def test_replan_hz_sets_how_often_the_planner_plans(tmp_path, hz):
    out = tmp_path / f"hz{hz}"
    assert main(["evaluate", "--planners", "cv", "--env", ENV, "--episodes", "1", "--seed", "11",
                 "--episode-s", "2", "--replan-hz", str(hz), "--out", str(out), "--quiet"]) == 0
    rows = (out / "episodes.csv").read_text().splitlines()
    record = dict(zip(rows[0].split(","), rows[1].split(",")))
    assert int(record["plan_calls"]) == 2 * hz             # 2 s of driving


def test_the_table_shows_display_names_and_the_records_keep_the_spec():
    named = "py:tests.broken_planners:Broken?fault=kmh&name=gk"
    source, planners = EnvSource(ENV, 1), ("idm", "riskmap:a/best", "riskmap:b/best", named)
    row = {"collided": False, "off_road": False, "failure": None, "dangerous": 0, "encounters": 1,
           **{key: 1.0 for key in evaluate_module.METRICS}}
    table = evaluate_module.summarise(source, planners, [{**row, "planner": spec} for spec in planners])
    assert list(table) == list(planners)                             # results.json: by SPEC
    assert [entry["name"] for entry in table.values()] == ["idm", "best", "best-2", "gk"]
    text = evaluate_module.markdown_table(source, table)
    assert "| gk | 1 |" in text and "| best-2 | 1 |" in text and "py:" not in text
    # episode folders stay named by the SPEC: --resume finds earlier runs' records there
    assert evaluate_module.planner_slug(named) == "py_tests_broken_planners_Broken_fault_kmh_name_gk"
    with pytest.raises(InputError, match="name='a/b'"):
        EnvSource(ENV, 1).check(("cv", "py:tests.broken_planners:Broken?name=a/b"))


def test_replan_hz_must_divide_the_control_rate():
    with pytest.raises(InputError, match="--replan-hz 3: must divide the 10 Hz"):
        EnvSource(ENV, 1, replan_hz=3)


@pytest.mark.slow
def test_implausible_plans_are_counted_per_run_and_named_under_the_table(tmp_path):
    """A planner whose plans are in km/h is still driven, and its run says so: results.json,
    episodes.csv and a line under the table. A planner that keeps the contract counts 0."""
    kmh = "py:tests.broken_planners:Broken?fault=kmh&name=kmh"
    out = tmp_path / "ev"
    assert main(["evaluate", "--planners", f"cv,{kmh}", "--env", ENV, "--episodes", "1", "--seed", "11",
                 "--episode-s", "2", "--out", str(out), "--quiet"]) == 0
    results = json.loads((out / "results.json").read_text())["planners"]
    assert results[kmh]["implausible_plans"] == 4 and results[kmh]["implausible_plan_episodes"] == 1
    assert results[kmh]["implausible_plan_first"].startswith("in episode 0 at 0.0 s: the first step implies")
    assert results["cv"]["implausible_plans"] == 0 and results["cv"]["implausible_plan_first"] is None
    rows = (out / "episodes.csv").read_text().splitlines()
    assert rows[0].endswith(",plan_calls,implausible_plans,no_solution_plans") and rows[1].endswith(",4,0,0")
    table = (out / "table.md").read_text()
    assert "Implausible plans" in table and "kmh: 4 plans in 1 of 1 episodes" in table and "km/h?" in table
    assert "cv:" not in table
