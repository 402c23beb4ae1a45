import dataclasses
import json

import numpy as np
import pytest

from rasterize.errors import InputError
from riskmap.data.collect import CollectConfig, run_episode
from riskmap.evaluation.drive import drive
from riskmap.figures.panels import missing_maps_note
from riskmap.registry import make_planner
from riskmap.sim.loop.plan import Plan
from riskmap.sim.worlds.episode import make_env
from riskmap.sim.worlds.highway_drive import DriveConfig


@pytest.mark.parametrize("human", ["yielding", "idm"])
def test_drive_replays_the_demonstrator(tmp_path, human):
    summary = drive(DriveConfig("intersection-v0", episodes=2, seed=11), human, tmp_path / "d",
                    progress=False)
    assert summary["summary"]["episodes"] == 2
    env = make_env("intersection-v0")
    for e in range(2):
        record = json.loads((tmp_path / "d" / "episodes" / f"episode_{e:06d}.json").read_text())
        _, info = run_episode(env, CollectConfig("intersection-v0", 2, seed=11, human=human), e)
        assert record["collided"] == info["ego_crashed"]
        assert record["simulated_s"] == pytest.approx(info["simulated_s"])
        assert record["driver"] == info["driver"]


def test_planner_drive_writes_episodes_frames_and_resumes(tmp_path, tiny_checkpoint):
    spec = f"riskmap:{tiny_checkpoint}"
    config = DriveConfig("intersection-v0", episodes=1, seed=11, episode_s=3.0)
    first = drive(config, spec, tmp_path / "p", frames=True, progress=False)
    record = json.loads((tmp_path / "p" / "episodes" / "episode_000000.json").read_text())
    assert record["plan_calls"] >= 1 and record["plan_ms_median"] > 0
    assert len(list((tmp_path / "p" / "frames").glob("*.png"))) == record["plan_calls"]
    with pytest.raises(InputError, match="--resume"):
        drive(config, spec, tmp_path / "p", progress=False)
    again = drive(config, spec, tmp_path / "p", resume=True, progress=False)
    assert again["summary"] == first["summary"]


def test_frames_of_a_planner_without_a_raster_and_of_one_that_makes_no_plans(tmp_path):
    config = DriveConfig("highway-v0", episodes=1, seed=0, episode_s=2.0)
    drive(config, "cv", tmp_path / "cv", frames=True, progress=False)       # drawn on the family's raster
    record = json.loads((tmp_path / "cv" / "episodes" / "episode_000000.json").read_text())
    assert len(list((tmp_path / "cv" / "frames").glob("*.png"))) == record["plan_calls"] >= 1
    drive(config, "idm", tmp_path / "idm", frames=True, progress=False)     # the scene at replan times
    record = json.loads((tmp_path / "idm" / "episodes" / "episode_000000.json").read_text())
    assert record["plan_calls"] == 0
    assert sorted(p.name for p in (tmp_path / "idm" / "frames").glob("*.png")) == [
        f"episode_000000_t{k:04d}.png" for k in (0, 5, 10, 15)]


def test_drive_frames_of_cv_from_the_command_line(tmp_path, monkeypatch):
    from riskmap.cli import main
    from riskmap.sim.worlds import highway_drive

    # The command line has no episode length: a 2 s highway episode keeps this to four frames.
    short = dataclasses.replace(highway_drive.FAMILY_SETUPS["highway"], episode_s=2.0)
    monkeypatch.setitem(highway_drive.FAMILY_SETUPS, "highway", short)
    out = tmp_path / "cv"
    assert main(["drive", "--frames", "--planner", "cv", "--env", "highway-v0", "--episodes", "1",
                 "--out", str(out), "--quiet"]) == 0
    frames = sorted((out / "frames").glob("*.png"))
    assert [p.name for p in frames] == [f"episode_000000_t{k:04d}.png" for k in (0, 5, 10, 15)]
    assert all(p.read_bytes().startswith(b"\x89PNG") for p in frames)


def test_a_frame_names_what_its_planner_lacks():
    waypoints = np.zeros((12, 2))
    assert missing_maps_note(Plan(waypoints), "cv") == "no risk map: cv"
    assert missing_maps_note(None, "idm") == "no plan, no risk map: idm drives itself"
    # A risk-map planner's frames keep their title as it was.
    assert missing_maps_note(Plan(waypoints, risk_map=np.zeros((4, 4))), "riskmap:ck") == ""


def test_unknown_spec():
    with pytest.raises(InputError, match="unknown planner spec"):
        make_planner("teleport")
