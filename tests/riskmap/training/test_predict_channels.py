"""Training with the predicted-future raster channels (`--predict-s`)."""

import json
import shutil

import numpy as np
import pytest
import torch

from rasterize.errors import InputError
from riskmap.cli import main
from riskmap.data.dataset import DemoDataset
from riskmap.planner.model import ModelConfig, RiskMapGenerator, load_model
from riskmap.planner.riskmap_planner import RiskMapPlanner
from riskmap.registry import make_planner
from riskmap.training.train import _init_from, train
from tests.riskmap.conftest import tiny_train_config


@pytest.fixture(scope="module")
def predict_run(tiny_dataset, tiny_checkpoint, tmp_path_factory):
    """A run fine-tuned with `--predict-s 2` from the 8-channel tiny checkpoint."""
    out = tmp_path_factory.mktemp("predict") / "run"
    assert main(["train", "--data", str(tiny_dataset), "--out", str(out), "--resolution", "25",
                 "--epochs", "1", "--batch-size", "4", "--max-windows", "4", "--predict-s", "2",
                 "--init-checkpoint", str(tiny_checkpoint), "--quiet"]) == 0
    return out / "best"


def _copy_checkpoint(checkpoint, to, edit):
    shutil.copy(checkpoint.with_suffix(".safetensors"), to.with_suffix(".safetensors"))
    side = json.loads(checkpoint.with_suffix(".json").read_text())
    edit(side)
    to.with_suffix(".json").write_text(json.dumps(side))
    return to


def test_init_checkpoint_grows_the_first_convolution_with_zeros(tiny_checkpoint):
    old, side = load_model(tiny_checkpoint)
    assert side["model"]["in_channels"] == 8
    config = ModelConfig(in_channels=10, resolution=side["model"]["resolution"])
    grown = RiskMapGenerator(config)
    _init_from(grown, config, tiny_checkpoint)
    grown.eval()
    weight = grown.backbone[0].weight.detach()
    assert weight.shape[1] == 10 and not weight[:, 8:].any()
    torch.testing.assert_close(weight[:, :8], old.backbone[0].weight.detach(), rtol=0, atol=0)
    # The new channels are off: whatever they hold, the network computes what the old one did.
    gen = torch.Generator().manual_seed(0)
    raster = torch.rand(2, 10, 200, 200, generator=gen)
    motion = torch.rand(2, 3, config.resolution, config.resolution, generator=gen)
    with torch.no_grad():
        torch.testing.assert_close(grown(raster, motion), old(raster[:, :8], motion),
                                   rtol=1e-5, atol=1e-6)


def test_init_checkpoint_refuses_other_networks(tiny_checkpoint, predict_run):
    other_resolution = ModelConfig(in_channels=10, resolution=50)
    with pytest.raises(InputError, match="--init-checkpoint"):
        _init_from(RiskMapGenerator(other_resolution), other_resolution, tiny_checkpoint)
    fewer = ModelConfig(in_channels=8, resolution=25)     # from the 10-channel run
    with pytest.raises(InputError, match="--init-checkpoint"):
        _init_from(RiskMapGenerator(fewer), fewer, predict_run)


def test_predict_s_is_saved_and_the_planner_draws_it(predict_run, tiny_dataset):
    side = json.loads(predict_run.with_suffix(".json").read_text())
    assert side["raster"]["predict_s"] == 2.0 and side["train"]["predict_s"] == 2.0
    assert side["model"]["in_channels"] == 10
    planner = RiskMapPlanner.load(predict_run)
    assert planner.raster.predict_s == 2.0
    plan = planner.plan(DemoDataset(tiny_dataset).scene(0))
    assert plan.waypoints.shape == (12, 2) and np.isfinite(plan.waypoints).all()


def test_a_sidecar_from_before_predict_s_plans_with_eight_channels(tiny_checkpoint, tiny_dataset,
                                                                   tmp_path):
    old = _copy_checkpoint(tiny_checkpoint, tmp_path / "old",
                           lambda side: side["raster"].pop("predict_s"))
    planner = RiskMapPlanner.load(old)
    assert planner.raster.predict_s == 0.0
    plan = planner.plan(DemoDataset(tiny_dataset).scene(0))
    assert np.isfinite(plan.waypoints).all()


def test_a_run_begun_before_predict_s_resumes(tiny_dataset, tmp_path):
    out = tmp_path / "run"
    train(tiny_train_config(tiny_dataset, out, epochs=1, max_windows=4), progress=False)
    side = json.loads((out / "last.json").read_text())
    del side["train"]["predict_s"]
    (out / "last.json").write_text(json.dumps(side))
    best = train(tiny_train_config(tiny_dataset, out, epochs=2, max_windows=4), resume=True,
                 progress=False)
    assert np.isfinite(best["val_ade_m"])
    with pytest.raises(InputError, match="other settings"):
        train(tiny_train_config(tiny_dataset, out, epochs=3, max_windows=4, predict_s=2.0),
              resume=True, progress=False)


def test_train_baseline_with_predict_s_builds_and_ships_ten_channels(tiny_dataset, tmp_path):
    out = tmp_path / "cnn"
    assert main(["train-baseline", "cnn", "--data", str(tiny_dataset), "--out", str(out),
                 "--epochs", "1", "--batch-size", "2", "--max-windows", "2", "--predict-s", "1.5",
                 "--quiet"]) == 0
    side = json.loads((out / "best.json").read_text())
    assert side["bc"]["in_channels"] == 10 and side["raster"]["predict_s"] == 1.5
    plan = make_planner(f"cnn:{out / 'best'}").plan(DemoDataset(tiny_dataset).scene(0))
    assert np.isfinite(plan.waypoints).all()


def test_predict_s_out_of_range_is_one_line(tiny_dataset, tmp_path, capsys):
    assert main(["train", "--data", str(tiny_dataset), "--out", str(tmp_path / "r"),
                 "--predict-s", "12", "--quiet"]) == 2
    assert "--predict-s" in capsys.readouterr().err
