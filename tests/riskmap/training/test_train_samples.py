"""How `riskmap train` makes its samples (cache, worker processes, memory layout) changes nothing
it computes."""

import numpy as np
import pytest
import torch
from safetensors.torch import load_file
from torch.utils.data import Subset

from rasterize.errors import InputError
from riskmap.data.dataset import DemoDataset, PerturbedEgo
from riskmap.data.sample_cache import open_sample_cache
from riskmap.training import train as train_module
from riskmap.training.train import _loader, same_settings, sample_workers, train
from tests.riskmap.conftest import tiny_train_config


def batches(dataset, order, workers) -> list[dict]:
    return list(_loader(Subset(dataset, order), 4, workers))


def assert_same_batches(a: list[dict], b: list[dict]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.keys() == y.keys()
        for key in x:
            assert torch.equal(x[key], y[key]), key


@pytest.mark.parametrize("use_cache", [False, True])
def test_worker_processes_give_the_batches_of_the_training_process(tiny_dataset, tmp_path, use_cache):
    dataset = DemoDataset(tiny_dataset, resolution=25)
    if use_cache:
        dataset.use_cache(open_sample_cache(dataset, tmp_path))
    augmented = PerturbedEgo(dataset, seed=5)
    augmented.set_epoch(2)
    order = torch.randperm(len(dataset), generator=torch.Generator().manual_seed(1)).tolist()[:10]
    inline = batches(augmented, order, 0)
    for workers in (1, 2):         # with the cache: the first pass filled it, these read it
        assert_same_batches(batches(augmented, order, workers), inline)
    plain = PerturbedEgo(DemoDataset(tiny_dataset, resolution=25), seed=5)
    plain.set_epoch(2)
    assert_same_batches(batches(plain, order, 0), inline)


def epoch_records(config, **kw) -> list[dict]:
    records = []
    train(config, progress=False, on_epoch=lambda epoch, record: records.append(record), **kw)
    return records


def test_a_run_with_cache_and_workers_computes_what_one_without_does(tiny_dataset, tmp_path):
    runs = {name: epoch_records(tiny_train_config(tiny_dataset, tmp_path / name, **settings))
            for name, settings in {"plain": {"cache": "off", "workers": 0},
                                   "fast": {"cache": str(tmp_path / "cache"), "workers": 2}}.items()}
    assert [r["losses"] for r in runs["fast"]] == [r["losses"] for r in runs["plain"]]
    assert [r["nlls"] for r in runs["fast"]] == [r["nlls"] for r in runs["plain"]]
    a, b = (load_file(str(tmp_path / name / "last.safetensors")) for name in ("plain", "fast"))
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0)
    logs = {name: [row.split(",")[:-1] for row in (tmp_path / name / "log.csv").read_text().splitlines()]
            for name in runs}
    assert logs["fast"] == logs["plain"]
    assert not (tmp_path / "plain" / "cache").exists()
    assert sorted(p.name.split("-")[0] for p in (tmp_path / "cache").iterdir()) == ["maps", "raster"]


def test_the_channels_last_network_trains_as_the_default_layout_within_rounding(tiny_dataset, tmp_path):
    losses = {layout: epoch_records(tiny_train_config(tiny_dataset, tmp_path / str(layout), epochs=1),
                                    channels_last=layout)[0]["losses"]
              for layout in (False, True)}
    np.testing.assert_allclose(losses[True], losses[False], rtol=1e-4)


def test_the_cache_goes_beside_the_data_else_into_the_run(tiny_dataset, tmp_path, monkeypatch):
    import shutil

    data = tmp_path / "data"
    shutil.copytree(tiny_dataset, data, ignore=shutil.ignore_patterns("cache"))
    train(tiny_train_config(data, tmp_path / "a", epochs=1, max_windows=4), progress=False)
    assert len(list((data / "cache").glob("raster-*"))) == 1

    opened = []

    def read_only_data(dataset, root):
        if root.parent == data:
            raise PermissionError(13, "Permission denied")
        opened.append(root)
        return open_sample_cache(dataset, root)

    monkeypatch.setattr(train_module, "open_sample_cache", read_only_data)
    train(tiny_train_config(data, tmp_path / "b", epochs=1, max_windows=4), progress=False)
    assert opened == [tmp_path / "b" / "cache"]
    with pytest.raises(InputError, match="--cache"):
        train(tiny_train_config(data, tmp_path / "c", epochs=1, max_windows=4, cache=str(data / "x")),
              progress=False)


def test_a_resume_may_change_how_samples_are_made(tiny_dataset, tmp_path):
    saved = tiny_train_config(tiny_dataset, tmp_path, workers=0, cache="off").__dict__
    saved = {k: list(v) if isinstance(v, tuple) else v for k, v in saved.items()}
    assert same_settings(saved, tiny_train_config(tiny_dataset, tmp_path, workers=2, cache="auto"))
    assert not same_settings(saved, tiny_train_config(tiny_dataset, tmp_path, lr=0.5))
    old = {k: v for k, v in saved.items() if k not in ("workers", "cache")}   # before they existed
    assert same_settings(old, tiny_train_config(tiny_dataset, tmp_path, workers=3))


def test_sample_workers_default_to_none_on_the_cpu():
    assert sample_workers(None, torch.device("cpu")) == 0
    assert sample_workers(3, torch.device("cpu")) == 3
    assert 0 <= sample_workers(None, torch.device("cuda")) <= 4


def test_the_sample_options_are_checked(tiny_dataset, tmp_path):
    with pytest.raises(InputError, match="--workers"):
        tiny_train_config(tiny_dataset, tmp_path, workers=-1)
    with pytest.raises(InputError, match="--cache"):
        tiny_train_config(tiny_dataset, tmp_path, cache="")
