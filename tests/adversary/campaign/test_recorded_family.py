"""Recorded scenario families: campaigns over scenes cut from CommonRoad recordings
(`scenarios: [{commonroad: FILES, episodes: N}]`), beside highway-env ones."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from adversary.attacks.recorded import RecordedScene, job_family, recorded_env_id
from adversary.campaign.config import campaign_from_dict
from adversary.campaign.run import RunOptions, run_campaign
from adversary.crash.recorded import candidates, sweep_files
from adversary.report.page import make_report
from rasterize.errors import InputError

ROOT = Path(__file__).resolve().parents[3]
FIXTURES = ROOT / "tests" / "fixtures" / "commonroad"
RECORDING = FIXTURES / "USA_US101-4_1_T-1.xml"        # 8 attackable vehicles
SHORT = FIXTURES / "USA_US101-3_3_T-1.xml"            # 3 s long: no attackable vehicle
ENV = recorded_env_id("us101")
CRASH = {"name": "crash", "params": {"selector": "nearest", "iterations": 4, "replan_every": 2,
                                     "traffic_model": "checkpoints/crash_traffic_highway"}}


def _config(scenarios, attacks=({"name": "natural"},), planners=("cv",), **changes):
    return {"name": "recorded", "seed": 0, "planners": list(planners), "scenarios": list(scenarios),
            "attacks": list(attacks), "budget": {"episode_s": 3.0}, "report": {"gallery": 2}, **changes}


def test_both_kinds_of_family_parse_into_jobs():
    config = campaign_from_dict(_config(
        [{"env": "highway-v0", "seed": 0, "episodes": 1},
         {"commonroad": str(RECORDING), "episodes": 2}]))       # one path: a list of one
    assert config.env_ids() == ["highway-v0", ENV] and job_family(ENV) == "us101"
    jobs = config.jobs()
    assert [(j.env_id, j.episode) for j in jobs] == [("highway-v0", 0), (ENV, 0), (ENV, 1)]
    assert jobs[0].scene is None
    scenes = [j.scene for j in jobs[1:]]
    assert all(isinstance(s, RecordedScene) and s.family == "us101" for s in scenes)
    # The sweep's first scenes, in its order: the same candidates `adversary scenes --commonroad` tries.
    kept, _, _ = sweep_files([RECORDING], None)
    todo = candidates(kept, 2.0)
    for scene in scenes:
        path, ego_id, t0_s, why = todo[scene.candidate]
        assert (Path(scene.recording), scene.ego_id, scene.t0_s, why) == (path, ego_id, t0_s, "")
    assert scenes[0].candidate < scenes[1].candidate
    assert len({j.job_id for j in jobs}) == 3 and "commonroad-us101-s0e1" in jobs[2].job_id
    again = campaign_from_dict(_config([{"env": "highway-v0", "seed": 0, "episodes": 1},
                                        {"commonroad": [str(FIXTURES / "*4_1_T-1.xml")], "episodes": 2}]))
    assert [j.job_id for j in again.jobs()] == [j.job_id for j in jobs]     # globs; stable ids
    plain = config.plain()["scenarios"]
    assert set(plain[0]) == {"env", "seed", "episodes", "planners"}       # as before recorded families
    assert set(plain[1]) == {"commonroad", "episodes", "family", "t0", "planners"}
    described = jobs[1].describe()
    assert described["recording"] == RECORDING.name and described["family"] == "us101"


def test_recorded_yaml_validates_on_the_fixture():
    data = yaml.safe_load((ROOT / "experiments" / "campaigns" / "recorded.yaml").read_text())
    [family] = data["scenarios"]
    assert family["episodes"] == 3 and {a["name"] for a in data["attacks"]} == {"natural", "crash"}
    family["commonroad"] = [str(RECORDING)]              # the user's recordings, here the fixture
    config = campaign_from_dict(data)
    assert len(config.jobs()) == 2 * 3 * 2 and config.env_ids() == [ENV]


def _unknown_site(tmp_path) -> str:
    path = tmp_path / "DEU_Town-1_1_T-1.xml"
    shutil.copy(RECORDING, path)
    return str(path)


@pytest.mark.parametrize("scenario, attacks, message", [
    ({"env": "highway-v0", "commonroad": str(RECORDING)}, None, "exactly one of env"),
    ({"episodes": 1}, None, "exactly one of env"),
    ({"commonroad": str(RECORDING), "seed": 1}, None, "seed does not apply to a family with commonroad"),
    ({"env": "highway-v0", "t0": 3.0}, None, "t0 does not apply to a family with env"),
    ({"commonroad": "nowhere/USA_US101-1_1_T-1.xml"}, None, "scenarios[0].commonroad nowhere"),
    ({"commonroad": ["nowhere/*.xml"]}, None, "nowhere/*.xml matches no file"),
    ({"commonroad": str(RECORDING), "episodes": 9}, None, "only 8 scene(s) that can be attacked"),
    ({"commonroad": str(SHORT)}, None, "hold no scene that can be attacked"),
    ({"commonroad": str(RECORDING), "t0": 2.2}, None, "t0 must be a multiple of 0.5"),
    ({"commonroad": str(RECORDING), "family": "US 101"}, None, "family 'US 101'"),
    ("unknown site", None, "add family: NAME"),
    ({"commonroad": str(RECORDING)}, [{"name": "aggressive_neighbour"}],
     ("attacks[0] (aggressive_neighbour) needs a highway-env world and cannot run on the recorded family "
      "commonroad:us101; remove the attack, or remove the family")),
    ({"commonroad": str(RECORDING)}, [{"name": "nsga2_search"}], "(nsga2_search) needs a highway-env world"),
])
def test_bad_recorded_families_are_one_line_errors(tmp_path, scenario, attacks, message):
    if scenario == "unknown site":
        scenario = {"commonroad": _unknown_site(tmp_path)}
    with pytest.raises(InputError) as info:
        campaign_from_dict(_config([scenario], attacks or ({"name": "natural"},)))
    assert message in str(info.value) and "\n" not in str(info.value)


def test_highway_only_attacks_name_the_fix_and_may_be_limited_to_highway():
    families = [{"env": "highway-v0", "episodes": 1}, {"commonroad": str(RECORDING), "episodes": 1}]
    with pytest.raises(InputError, match=r"add envs: \[highway-v0\] to the attack, or remove the family"):
        campaign_from_dict(_config(families, [{"name": "natural"}, {"name": "aggressive_neighbour"}]))
    config = campaign_from_dict(_config(families, [{"name": "natural"},
                                                   {"name": "aggressive_neighbour", "envs": ["highway-v0"]}]))
    assert [(j.env_id, j.attack) for j in config.jobs()] == [
        ("highway-v0", "natural"), ("highway-v0", "aggressive_neighbour"), (ENV, "natural")]
    # the unknown site's family given by name
    named = campaign_from_dict(_config([{"commonroad": str(RECORDING), "family": "town"}]))
    assert named.env_ids() == ["commonroad:town"]
    with pytest.raises(InputError, match="two scenario families are the recorded family commonroad:us101"):
        campaign_from_dict(_config([families[1], {"commonroad": str(RECORDING), "t0": 2.5}]))


def test_recorded_campaign_runs_resumes_and_reports(tmp_path):
    """cv on a highway scene (natural) and on the first recorded scene (natural, crash); split over
    two sittings, then the report."""
    data = _config([{"env": "highway-v0", "seed": 0, "episodes": 1},
                    {"commonroad": str(RECORDING), "episodes": 1}],
                   [{"name": "natural"}, {**CRASH, "envs": [ENV]}])
    config = campaign_from_dict(data)
    out = tmp_path / "campaign"
    first = run_campaign(config, out, RunOptions(max_jobs=2, progress=False))
    assert first == {"total": 3, "finished": 2, "ran": 2, "failed": 0, "collided": first["collided"]}
    kept = {p.name: p.read_text() for p in (out / "records").glob("*.json")}
    counts = run_campaign(campaign_from_dict(data), out, RunOptions(resume=True, progress=False))
    assert counts["finished"] == counts["total"] == 3 and counts["ran"] == 1 and counts["failed"] == 0
    assert all((out / "records" / name).read_text() == text for name, text in kept.items())
    again = run_campaign(campaign_from_dict(data), out, RunOptions(resume=True, progress=False))
    assert again["ran"] == 0
    records = {r["attack"] + "@" + r["env_id"]: r for r in
               (json.loads(p.read_text()) for p in (out / "records").glob("*.json"))}
    assert set(records) == {"natural@highway-v0", f"natural@{ENV}", f"crash@{ENV}"}
    natural, crash = records[f"natural@{ENV}"], records[f"crash@{ENV}"]
    for r in (natural, crash):
        assert r["status"] == "ok", r.get("error")
        assert (r["family"], r["recording"], r["ego_id"]) == ("us101", RECORDING.name, 400)
    # natural: the drive's EpisodeRecord and the monitor's fields, as on a simulated scene
    assert set(records["natural@highway-v0"]) - {"family", "recording", "ego_id", "t0_s"} <= set(natural)
    assert natural["simulated_s"] == pytest.approx(6.0) and natural["distance_m"] > 0
    assert natural["encounters"] > 0 and 0 <= natural["safety_pct"] <= 100
    assert natural["has_adversary"] is False and natural["attack_extra"]["contact"] == (
        None if not natural["collided"] else natural["attack_extra"]["contact"])
    assert crash["attacked"] is True and crash["attack_extra"]["iterations"] == 4
    with np.load(out / "artifacts" / f"{natural['job_id']}.npz") as art:
        assert "final__states" in art.files and "plan__waypoints" in art.files
    with np.load(out / "artifacts" / f"{crash['job_id']}.npz") as art:
        assert "final__states" in art.files                   # keep_scenes: the report's frames

    report = make_report(out, tmp_path / "report")
    families = {row["family"] for row in report["results"]["by_family"]}
    assert families == {"highway", "us101"}
    html = (tmp_path / "report" / "report.html").read_text()
    assert ENV in html and f"{RECORDING.name} vehicle 400" in html
    for r in (natural, crash):
        page = tmp_path / "report" / report["pages"][r["job_id"]]
        text = page.read_text()
        assert "USA_US101-4_1_T-1 vehicle 400" in text
        assert (tmp_path / "report" / "jobs" / "media" / f"{r['job_id']}_strip.png").is_file()
