
from dataclasses import replace

import pytest
import torch

from rasterize.config import Extent, RasterConfig
from rasterize.errors import InputError
from rasterize.raster import CHANNELS, channels
from riskmap.data.collect import CollectConfig, collect, shard_path
from riskmap.data.dataset import DemoDataset, collected_raster_config


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("data") / "highway"
    collect(CollectConfig("highway-v0", episodes=1, seed=0), d, progress=False)
    return d


@pytest.mark.parametrize("resolution", [25, 50])
def test_samples_have_the_documented_shapes(dataset_dir, resolution):
    ds = DemoDataset(dataset_dir, resolution=resolution)
    assert len(ds) == 33                              # 40 s episode: windows at t = 2 .. 34 s
    sample = ds[5]
    g = resolution
    assert sample["raster"].shape == (len(CHANNELS), 200, 200)
    assert sample["motion"].shape == (3, g, g) and sample["demo"].shape == (2, g, g)
    assert sample["uncertainty"].shape == (g, g) and sample["goal_map"].shape == (g, g)
    assert sample["future"].shape == (12, 2) and sample["start_cell"].dtype == torch.int64
    for value in sample.values():
        assert torch.isfinite(value.float()).all()
    # D_demo starts at the ego's cell; the goal map peaks at the goal cell, ahead of the ego.
    r, c = sample["start_cell"].tolist()
    assert sample["demo"][0, r, c] >= 1
    gr, gc = sample["goal_cell"].tolist()
    assert sample["goal_map"][gr, gc] == pytest.approx(1.0) and gr < r
    # Highway ego drives forward: its last waypoint is well ahead.
    assert sample["future"][-1, 0] > 50.0


def test_demo_goal_option_uses_the_demonstration_end(dataset_dir):
    sample = DemoDataset(dataset_dir, goal="demo")[3]
    goal = torch.nonzero(sample["demo"][1])[0].tolist()
    assert sample["goal_cell"].tolist() == goal
    with pytest.raises(InputError, match="goal must be"):
        DemoDataset(dataset_dir, goal="nowhere")


def test_batches_through_a_dataloader(dataset_dir):
    loader = torch.utils.data.DataLoader(DemoDataset(dataset_dir), batch_size=4)
    batch = next(iter(loader))
    assert batch["raster"].shape[0] == 4 and batch["demo"].shape == (4, 2, 50, 50)


def test_another_raster_config_is_refused(dataset_dir):
    other = RasterConfig(Extent(60.0, 20.0, 40.0, 40.0))
    with pytest.raises(InputError, match="collected with raster config"):
        DemoDataset(dataset_dir, raster=other)
    # Another predict_s does not make another extent acceptable.
    with pytest.raises(InputError, match="collected with raster config"):
        DemoDataset(dataset_dir, raster=replace(other, predict_s=3.0))


def test_a_raster_differing_only_in_predict_s_draws_the_predicted_future(dataset_dir):
    collected = collected_raster_config(dataset_dir)
    assert collected.predict_s == 0.0
    plain = DemoDataset(dataset_dir)
    ahead = DemoDataset(dataset_dir, raster=replace(collected, predict_s=3.0))
    assert ahead.raster_config.predict_s == 3.0 and plain.raster_config == collected
    a, b = plain[5]["raster"], ahead[5]["raster"]
    assert b.shape == (len(channels(ahead.raster_config)), 200, 200) == (10, 200, 200)
    torch.testing.assert_close(b[:8], a, rtol=0, atol=0)
    # Highway traffic is moving: the other agents' future is drawn; highway-env has no lights.
    assert b[channels(ahead.raster_config).index("agents_future")].any()
    assert not b[channels(ahead.raster_config).index("signal_red")].any()


def test_corrupt_and_empty_shards_are_named(tmp_path, dataset_dir):
    import shutil

    d = tmp_path / "copy"
    shutil.copytree(dataset_dir, d)
    shard_path(d, 0).write_bytes(b"")
    with pytest.raises(InputError, match="episode_000000.npz is corrupt"):
        DemoDataset(d)
    shard_path(d, 0).unlink()
    with pytest.raises(InputError, match="missing"):
        DemoDataset(d)
    with pytest.raises(InputError, match="not a dataset"):
        DemoDataset(tmp_path / "nowhere")


def test_perturbed_ego_is_deterministic_per_epoch_and_keeps_the_future(dataset_dir):
    from riskmap.data.dataset import PerturbedEgo

    base = DemoDataset(dataset_dir)
    aug = PerturbedEgo(base, seed=1, probability=1.0, max_heading_deg=10, max_lateral_m=1.0)
    aug.set_epoch(3)
    a, b = aug[7], aug[7]
    torch.testing.assert_close(a["raster"], b["raster"])
    aug.set_epoch(4)
    c = aug[7]
    assert not torch.equal(a["raster"], c["raster"])
    # The recorded future is the same path, seen from a slightly different pose.
    assert torch.linalg.norm(a["future"] - base[7]["future"], dim=1).max() < 0.2 * 150 + 1.0
