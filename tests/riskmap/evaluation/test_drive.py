import json

import pytest

from rasterize.errors import InputError
from riskmap.data.collect import CollectConfig, run_episode
from riskmap.evaluation.drive import drive
from riskmap.registry import make_planner
from riskmap.sim.episode import make_env
from riskmap.sim.rollout import DriveConfig


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
    with pytest.raises(InputError, match="idm makes none"):
        drive(config, "idm", tmp_path / "idm", frames=True, progress=False)
    assert not (tmp_path / "idm").exists()                  # refused before anything is written


def test_unknown_spec():
    with pytest.raises(InputError, match="unknown planner spec"):
        make_planner("teleport")
