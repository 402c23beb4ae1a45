import json

import numpy as np
import pytest

from riskmap.data.dataset import DemoDataset, PerturbedEgo
from riskmap.data.sample_cache import CHECK, open_sample_cache


def assert_same_sample(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key, value in a.items():
        assert value.dtype == b[key].dtype, key
        assert np.array_equal(value.numpy(), b[key].numpy()), key


def folders(dataset) -> dict:
    return {name: folder.directory for name, folder in dataset.cache.folders.items()}


def cached(data, root, **settings) -> DemoDataset:
    dataset = DemoDataset(data, **settings)
    dataset.use_cache(open_sample_cache(dataset, root))
    return dataset


def test_a_cached_sample_equals_the_freshly_built_one(tiny_dataset, tmp_path):
    fresh, dataset = DemoDataset(tiny_dataset, resolution=25), cached(tiny_dataset, tmp_path, resolution=25)
    indices = range(0, len(fresh), 3)
    for i in indices:                                   # built and stored
        assert_same_sample(dataset[i], fresh[i])
    assert dataset.cache.misses == len(indices) and dataset.cache.hits == 0
    for i in indices:                                   # read back
        assert_same_sample(dataset[i], fresh[i])
    assert dataset.cache.hits == len(indices)
    # Another process opening the folders reads what this one stored.
    again = cached(tiny_dataset, tmp_path, resolution=25)
    assert folders(again) == folders(dataset)
    assert_same_sample(again[indices[-1]], fresh[indices[-1]]) and again.cache.hits == 1


def test_perturbed_and_unperturbed_windows_equal_the_uncached_ones(tiny_dataset, tmp_path):
    plain = PerturbedEgo(DemoDataset(tiny_dataset, resolution=25), seed=3)
    dataset = cached(tiny_dataset, tmp_path, resolution=25)
    augmented = PerturbedEgo(dataset, seed=3)
    kinds = set()
    for epoch in (0, 1):
        plain.set_epoch(epoch)
        augmented.set_epoch(epoch)
        for i in range(len(dataset)):
            kinds.add(augmented.perturbation(i) is None)
            assert_same_sample(augmented[i], plain[i])
    assert kinds == {True, False}                       # both kinds were compared
    assert dataset.cache.hits > 0                       # epoch 1 read windows epoch 0 stored


def test_another_setting_makes_another_cache(tiny_dataset, tmp_path):
    from dataclasses import replace

    from riskmap.data.dataset import collected_raster_config

    base = cached(tiny_dataset, tmp_path, resolution=25)
    base[0]
    changes = [{"resolution": 50}, {"sigma_x": 0.7}, {"sigma_y": 2.0}, {"goal": "demo"},
               {"goal_variance": 2.0}]
    maps = {folders(base)["maps"]}
    for change in changes:
        settings = {"resolution": 25} | change
        other = cached(tiny_dataset, tmp_path, **settings)
        maps.add(folders(other)["maps"])
        assert folders(other)["raster"] == folders(base)["raster"]     # the same raster
        assert other.cache.filled() == 0 and other.cache.get(0) is None   # rebuilt maps
        assert_same_sample(other[0], DemoDataset(tiny_dataset, **settings)[0])
    assert len(maps) == 1 + len(changes)
    # Another raster (here: with the predicted future) makes another raster folder too.
    raster = replace(collected_raster_config(tiny_dataset), predict_s=2.0)
    other = cached(tiny_dataset, tmp_path, resolution=25, raster=raster)
    assert folders(other)["raster"] != folders(base)["raster"] and other.cache.get(0) is None
    assert_same_sample(other[0], DemoDataset(tiny_dataset, resolution=25, raster=raster)[0])


def test_a_changed_dataset_makes_another_cache(tiny_dataset, tmp_path):
    import shutil

    copy = tmp_path / "data"
    shutil.copytree(tiny_dataset, copy, ignore=shutil.ignore_patterns("cache"))
    before = folders(cached(copy, tmp_path / "cache"))
    index = json.loads((copy / "index.json").read_text())
    (copy / "index.json").write_text(json.dumps(index, indent=1))   # same windows, other bytes
    after = folders(cached(copy, tmp_path / "cache"))
    assert all(after[name] != before[name] for name in before)


def test_a_damaged_window_is_built_again(tiny_dataset, tmp_path):
    fresh, dataset = DemoDataset(tiny_dataset, resolution=25), cached(tiny_dataset, tmp_path, resolution=25)
    dataset[2], dataset[4]
    raster = np.load(folders(dataset)["raster"] / "raster.npy", mmap_mode="r+")
    raster[2] = 255 - raster[2]                         # flipped bytes
    raster.flush()
    check = np.load(folders(dataset)["maps"] / CHECK, mmap_mode="r+")
    check[4] = np.uint64(12345)                         # a checksum that fits no bytes
    check.flush()
    reopened = cached(tiny_dataset, tmp_path, resolution=25)
    for i in (2, 4):
        assert_same_sample(reopened[i], fresh[i])
    assert reopened.cache.misses == 2 and reopened.cache.hits == 0
    assert_same_sample(reopened[2], fresh[2]) and reopened.cache.hits == 1   # stored again


@pytest.mark.parametrize("damage", ["truncate", "meta", "missing"])
def test_a_damaged_cache_folder_is_made_anew(tiny_dataset, tmp_path, damage):
    fresh, dataset = DemoDataset(tiny_dataset, resolution=25), cached(tiny_dataset, tmp_path, resolution=25)
    dataset[1]
    before = folders(dataset)
    del dataset
    if damage == "truncate":
        path = before["raster"] / "raster.npy"
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    elif damage == "meta":
        (before["maps"] / "meta.json").write_text("{not json")
    else:
        (before["maps"] / "motion.npy").unlink()
    reopened = cached(tiny_dataset, tmp_path, resolution=25)
    assert folders(reopened) == before and reopened.cache.filled() == 0
    assert_same_sample(reopened[1], fresh[1])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]   # no leftovers


def test_a_cache_sent_to_a_spawned_worker_maps_the_same_folders(tiny_dataset, tmp_path):
    import pickle

    fresh, dataset = DemoDataset(tiny_dataset, resolution=25), cached(tiny_dataset, tmp_path, resolution=25)
    dataset[3]
    copy = pickle.loads(pickle.dumps(dataset.cache))
    assert len(pickle.dumps(dataset.cache)) < 10_000                  # the folders, not the arrays
    arrays = copy.get(3)
    assert arrays is not None and all(np.array_equal(arrays[k], v)
                                      for k, v in fresh.sample_arrays(fresh.scene(3)).items())


def test_a_full_disk_gives_up_the_cache_not_the_sample(tiny_dataset, tmp_path, monkeypatch):
    import errno
    import os

    fresh, dataset = DemoDataset(tiny_dataset, resolution=25), cached(tiny_dataset, tmp_path, resolution=25)

    def full(fd, offset, length):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "posix_fallocate", full)
    with pytest.warns(UserWarning, match="sample cache given up"):
        assert_same_sample(dataset[5], fresh[5])
    assert dataset.cache is None
    assert_same_sample(dataset[6], fresh[6])
