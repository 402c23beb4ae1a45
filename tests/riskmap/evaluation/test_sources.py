"""Scenario sources: the episodes each yields, and one set of output files whatever the source."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from riskmap.evaluation.evaluate import CSV_FIELDS, evaluate
from riskmap.evaluation.sources import EnvSource, RecordingSource

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"
ENV = "intersection-v0"


def test_env_source_yields_its_seeds_episodes_under_the_record_names_of_earlier_runs():
    source = EnvSource(ENV, 3, seed=11)
    assert [(s.id, s.label) for s in source.scenarios()] == [
        ("episode_000000", 0), ("episode_000001", 1), ("episode_000002", 2)]
    # run.json keeps the layout of runs made before sources, so they resume
    config = source.settings(("idm", "cv"))["config"]
    assert config["planners"] == ["idm", "cv"] and config["episodes"] == 3 and config["seed"] == 11
    assert set(config) == {"env_id", "planners", "episodes", "seed", "mode", "control_hz", "replan_hz",
                           "episode_s", "safety"}


@pytest.mark.slow
def test_recording_source_yields_the_same_vehicles_as_before():
    """Every demonstrator once, in file order; --max-episodes N: N of them drawn with the seed and
    kept in file order (the choice evaluate --commonroad made before sources)."""
    from riskmap.data.collect_commonroad import CommonRoadCollectConfig, scenario_files, unique_demonstrators

    files = scenario_files([FIXTURES], flag="--commonroad")
    demos, traffics, _ = unique_demonstrators(files, CommonRoadCollectConfig(files=(), smoothing_s=0.0))
    every = [f"{traffics[d.path].name}_{int(traffics[d.path].ids[d.agent])}" for d in demos]
    assert [s.id for s in RecordingSource((str(FIXTURES),)).scenarios()] == every
    for seed in (0, 3):
        keep = np.sort(np.random.default_rng(seed).choice(len(every), 2, replace=False))
        chosen = RecordingSource((str(FIXTURES),), seed=seed, limit=2).scenarios()
        assert [s.id for s in chosen] == [every[i] for i in keep]
        assert all(s.label == s.id for s in chosen)


@pytest.mark.slow
def test_both_sources_write_the_same_files_with_the_same_columns(tmp_path):
    env_out, cr_out = tmp_path / "env", tmp_path / "cr"
    evaluate(EnvSource(ENV, 1, seed=11, episode_s=2.0), ("idm", "cv"), env_out, progress=False)
    evaluate(RecordingSource((str(FIXTURES / "USA_US101-4_1_T-1.xml"),), limit=1), ("replay", "cv"), cr_out,
             progress=False)
    for out in (env_out, cr_out):
        assert {p.name for p in out.iterdir()} >= {"episodes.csv", "results.json", "table.md", "run.json"}
    rows = {name: list(csv.DictReader((out / "episodes.csv").open()))
            for name, out in (("env", env_out), ("cr", cr_out))}
    assert all(list(r[0]) == list(CSV_FIELDS) and len(r) == 2 for r in rows.values())
    assert [r["episode"] for r in rows["env"]] == ["0", "0"]
    cr_episode = next((cr_out / "episodes" / "cv").glob("*.json")).stem
    assert [r["episode"] for r in rows["cr"]] == [cr_episode, cr_episode]
    # a column that does not apply is empty in the CSV and "–" in the table
    assert rows["cr"][0]["jerk_mps3"] == "" and rows["env"][1]["red_light_violations"] == ""
    tables = [(out / "table.md").read_text().splitlines() for out in (env_out, cr_out)]
    assert tables[0][2] == tables[1][2]                           # one header
    assert tables[1][4].split(" | ")[-2] == "–"                    # jerk on recordings
    results = [json.loads((out / "results.json").read_text()) for out in (env_out, cr_out)]
    assert [r["source"] for r in results] == ["env", "commonroad"]
    assert all(r["planners"] == r["results"] for r in results)      # the old name of either layout
    assert set(results[0]["planners"]["cv"]) <= set(results[1]["planners"]["cv"]) | {
        "red_light_violations"}
