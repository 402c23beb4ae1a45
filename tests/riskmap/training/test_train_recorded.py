"""Training on recorded traffic end to end: configurations held out, the data's settings in the
checkpoint, the planner and the replay using them, the planning goal variance tuned per goal on
training configurations."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

pytest.importorskip("commonroad")

from rasterize.commonroad import CommonRoadSceneConfig
from riskmap.cli import main
from riskmap.data.collect_commonroad import collect_commonroad
from riskmap.planner.riskmap_planner import RiskMapPlanner
from riskmap.sim.worlds.commonroad_replay import route_scene_config
from riskmap.training.config import TrainConfig
from riskmap.training.train import train

RECORDING = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad" / "USA_US101-4_1_T-1.xml"


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("recorded_run")
    folder = root / "recordings"
    folder.mkdir()
    for name in ("USA_US101-4_1_T-1.xml", "USA_US101-5_1_T-1.xml"):
        shutil.copy(RECORDING, folder / name)
    data = root / "data"
    collect_commonroad([folder], data, progress=False)
    out = root / "run"
    train(TrainConfig(data=str(data), out=str(out), resolution=25, epochs=1, batch_size=4,
                      max_windows=8, val_ade_windows=2, lr=1e-3, val_groups=("5",)), progress=False)
    return data, out / "best"


def test_the_checkpoint_records_the_split_and_the_data_derived_settings(recorded_run):
    data, checkpoint = recorded_run
    side = json.loads(checkpoint.with_suffix(".json").read_text())
    derived = json.loads((data / "manifest.json").read_text())["derived"]
    assert side["dataset"]["val_groups"] == ["USA_US101-5"] and side["dataset"]["derived"] == derived
    assert side["raster"]["extent"] == derived["extent"]
    # Goal variance resolved from the data's goal error (none was given), used by the IRL loss.
    assert side["maps"]["goal_variance"] == side["irl"]["goal_variance"] > 0
    assert side["train"]["goal_variance"] is None and side["sampler"]["timing"] == "kinematic"
    planner = RiskMapPlanner.load(checkpoint)
    assert planner.route_settings == {"speed_limit_mps": derived["speed_limit_mps"],
                                      "route_accel_mps2": derived["route_accel_mps2"]}
    scene = route_scene_config(planner)
    assert scene.speed_limit_mps == derived["speed_limit_mps"]
    assert scene.route_rule.accel_mps2 == derived["route_accel_mps2"]
    assert route_scene_config(object()) == CommonRoadSceneConfig()   # planners without data settings


def test_tuning_per_goal_on_training_configurations(recorded_run, tmp_path, capsys):
    data, trained = recorded_run
    checkpoint = tmp_path / "best"
    for suffix in (".safetensors", ".json"):
        shutil.copy(trained.with_suffix(suffix), checkpoint.with_suffix(suffix))
    assert main(["tune-goal-variance", "--checkpoint", str(checkpoint), "--data", str(data),
                 "--goal", "human", "--groups", "4", "--candidates", "2,0.5", "--limit", "3",
                 "--timing", "uniform"]) == 0
    planning = json.loads(checkpoint.with_suffix(".json").read_text())["planning"]
    ades = {row["goal_variance"]: row["ade_m"] for row in planning["human_candidates"]}
    assert set(ades) == {2.0, 0.5} and planning["human_goal_variance"] == min(ades, key=ades.get)
    assert planning["human_groups"] == ["4"] and "goal_variance" not in planning
    assert planning["timing"] == "uniform" and RiskMapPlanner.load(checkpoint).sampler.timing == "uniform"
    assert "planning.human_goal_variance" in capsys.readouterr().out
    assert main(["tune-goal-variance", "--checkpoint", str(checkpoint), "--data", str(data),
                 "--groups", "9", "--candidates", "2", "--dry-run"]) == 2
    assert "no such group" in capsys.readouterr().err


def test_a_run_with_held_out_configurations_resumes(recorded_run, tmp_path):
    data, _ = recorded_run
    settings = dict(data=str(data), out=str(tmp_path / "run"), resolution=25, batch_size=4,
                    max_windows=8, val_ade_windows=2, lr=1e-3, val_groups=("5",))
    train(TrainConfig(epochs=1, **settings), progress=False)
    train(TrainConfig(epochs=2, **settings), resume=True, progress=False)   # JSON lists vs tuples
    assert json.loads((tmp_path / "run" / "last.json").read_text())["epoch"] == 1


def test_panels_of_held_out_configurations_towards_the_human_goal(recorded_run, tmp_path):
    data, checkpoint = recorded_run
    out = tmp_path / "fig"
    assert main(["figures", "plans", "--checkpoint", str(checkpoint), "--data", str(data),
                 "--out", str(out), "--count", "2", "--groups", "5", "--goal", "human"]) == 0
    # Configuration 5 holds the second half of the windows (18 of 36).
    names = sorted(p.name for p in out.glob("plan_*.png"))
    assert len(names) == 2 and all(int(n[5:10]) >= 18 for n in names)
