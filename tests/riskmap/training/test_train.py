import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from rasterize.errors import InputError
from riskmap.data.dataset import DemoDataset
from riskmap.planner.riskmap_planner import RiskMapPlanner
from riskmap.training.train import train
from tests.riskmap.conftest import tiny_train_config


def test_resume_continues_an_interrupted_run_exactly(tiny_dataset, tmp_path):
    full, cut = tmp_path / "full", tmp_path / "cut"
    train(tiny_train_config(tiny_dataset, full, epochs=2), progress=False)
    train(tiny_train_config(tiny_dataset, cut, epochs=1), progress=False)
    with pytest.raises(InputError, match="--resume"):
        train(tiny_train_config(tiny_dataset, cut, epochs=2), progress=False)
    train(tiny_train_config(tiny_dataset, cut, epochs=2), resume=True, progress=False)
    a, b = load_file(str(full / "last.safetensors")), load_file(str(cut / "last.safetensors"))
    assert a.keys() == b.keys()
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0)
    rows = lambda p: [r.split(",")[:-1] for r in (p / "log.csv").read_text().splitlines()]
    assert rows(full) == rows(cut)
    with pytest.raises(InputError, match="other settings"):
        train(tiny_train_config(tiny_dataset, cut, epochs=3, lr=0.5), resume=True, progress=False)


def test_run_writes_logs_and_a_loadable_checkpoint(tiny_checkpoint):
    run = tiny_checkpoint.parent
    assert (run / "log.csv").read_text().count("\n") == 3          # header + 2 epochs
    assert any((run / "tb").iterdir())
    planner = RiskMapPlanner.load(tiny_checkpoint, seed=1)
    scene = DemoDataset(planner_data_dir(tiny_checkpoint)).scene(0)
    plan_a, plan_b = planner.plan(scene), RiskMapPlanner.load(tiny_checkpoint, seed=1).plan(scene)
    assert plan_a.waypoints.shape == (12, 2) and np.isfinite(plan_a.waypoints).all()
    np.testing.assert_array_equal(plan_a.waypoints, plan_b.waypoints)
    assert plan_a.risk_map.shape == (25, 25) and (plan_a.risk_map <= 0).all()
    assert plan_a.policy.shape == (5, 25, 25)
    assert set(plan_a.timings_s) >= {"raster", "network", "vi", "sampler", "total"}
    assert plan_a.svf.shape == (25, 25) and "svf" in plan_a.timings_s     # computed when read


def planner_data_dir(checkpoint):
    import json

    return json.loads(checkpoint.with_suffix(".json").read_text())["train"]["data"]


@pytest.mark.parametrize("resolution", [25, 50, 75, 100])
def test_every_resolution_trains_a_step(tiny_dataset, tmp_path, resolution):
    best = train(tiny_train_config(tiny_dataset, tmp_path / "r", resolution=resolution, epochs=1,
                                   max_windows=4, val_ade_windows=1), progress=False)
    assert np.isfinite(best["val_nll"]) and np.isfinite(best["val_ade_m"])


def test_planning_goal_variance_comes_from_argument_then_sidecar_then_training(tiny_checkpoint,
                                                                               tmp_path):
    import json
    import shutil

    trained = RiskMapPlanner.load(tiny_checkpoint)
    assert trained.goal_variance == json.loads(
        tiny_checkpoint.with_suffix(".json").read_text())["irl"]["goal_variance"]
    assert RiskMapPlanner.load(tiny_checkpoint, goal_variance=0.7).goal_variance == 0.7
    copy = tmp_path / "tuned"
    shutil.copy(tiny_checkpoint.with_suffix(".safetensors"), copy.with_suffix(".safetensors"))
    side = json.loads(tiny_checkpoint.with_suffix(".json").read_text())
    side["planning"] = {"goal_variance": 1.5}
    copy.with_suffix(".json").write_text(json.dumps(side))
    assert RiskMapPlanner.load(copy).goal_variance == 1.5
    assert RiskMapPlanner.load(copy, goal_variance=3.0).goal_variance == 3.0
    with pytest.raises(InputError, match="goal variance"):
        RiskMapPlanner.load(copy, goal_variance=0.0)


def test_a_narrower_goal_ends_plans_nearer_the_goal(tiny_checkpoint):
    from rasterize.frames import ego_from_grid

    scene = DemoDataset(planner_data_dir(tiny_checkpoint)).scene(0)
    errors = []
    for variance in (50.0, 0.2):
        plan = RiskMapPlanner.load(tiny_checkpoint, seed=3, goal_variance=variance).plan(scene)
        grid = RiskMapPlanner.load(tiny_checkpoint).grid
        errors.append(np.linalg.norm(plan.waypoints[-1] - ego_from_grid(plan.goal_cell, grid)))
    assert errors[1] < errors[0]


def test_a_run_begun_before_state_pt_resumes_from_its_last_checkpoint(tiny_dataset, tmp_path):
    """Runs written before state.pt held last.*, last_optimizer.pt and log.csv (where a kill could
    leave a row twice): they resume from those, and their log is written again without the repeat."""
    full, old = tmp_path / "full", tmp_path / "old"
    train(tiny_train_config(tiny_dataset, full, epochs=2), progress=False)
    train(tiny_train_config(tiny_dataset, old, epochs=1), progress=False)
    torch.save(torch.load(old / "state.pt", weights_only=True)["optimizer"], old / "last_optimizer.pt")
    (old / "state.pt").unlink()
    log = (old / "log.csv").read_text()
    (old / "log.csv").write_text(log + log.splitlines()[-1] + "\n")
    train(tiny_train_config(tiny_dataset, old, epochs=2), resume=True, progress=False)
    a, b = load_file(str(full / "last.safetensors")), load_file(str(old / "last.safetensors"))
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0)
    rows = lambda p: [r.split(",")[:-1] for r in (p / "log.csv").read_text().splitlines()]
    assert rows(full) == rows(old)
