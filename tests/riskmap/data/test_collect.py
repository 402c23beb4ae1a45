import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from rasterize.errors import InputError
from riskmap.data.collect import CollectConfig, collect, shard_path

ENV = "intersection-v0"   # the shortest episodes


def _load(path):
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def _assert_same_dataset(a, b, episodes):
    for e in range(episodes):
        x, y = _load(shard_path(a, e)), _load(shard_path(b, e))
        assert x.keys() == y.keys()
        for k in x:
            np.testing.assert_array_equal(x[k], y[k], err_msg=f"episode {e} array {k}")


def test_collect_writes_shards_index_and_manifest(tmp_path):
    manifest = collect(CollectConfig(ENV, episodes=2, seed=5), tmp_path / "d", progress=False)
    d = tmp_path / "d"
    assert (d / "manifest.json").exists() and (d / "index.json").exists()
    index = json.loads((d / "index.json").read_text())
    assert [s["episode"] for s in index["shards"]] == [0, 1]
    assert manifest["counts"]["episodes"] == 2
    assert manifest["counts"]["windows"] == sum(s["windows"] for s in index["shards"]) > 0
    assert manifest["config"]["raster"]["extent"]["front_m"] == 60.0
    assert manifest["git_commit"] and manifest["package_version"]
    shard = _load(shard_path(d, 0))
    w, n, t, _ = shard["states"].shape
    assert t == 17 and n <= 32 and (shard["current_index"] == 4).all()
    assert not list(d.glob("**/*.tmp"))


def test_same_seed_same_data_and_workers_do_not_change_it(tmp_path):
    collect(CollectConfig(ENV, episodes=3, seed=1), tmp_path / "a", workers=1, progress=False)
    collect(CollectConfig(ENV, episodes=3, seed=1), tmp_path / "b", workers=2, progress=False)
    _assert_same_dataset(tmp_path / "a", tmp_path / "b", 3)


def test_different_seed_different_data(tmp_path):
    collect(CollectConfig(ENV, episodes=1, seed=1), tmp_path / "a", progress=False)
    collect(CollectConfig(ENV, episodes=1, seed=2), tmp_path / "b", progress=False)
    info_a, info_b = (json.loads(bytes(_load(shard_path(tmp_path / d, 0))["episode_info"]))
                      for d in "ab")
    assert info_a["seed"] != info_b["seed"] and info_a["driver"] != info_b["driver"]


def test_resume_after_interruption_gives_the_uninterrupted_result(tmp_path):
    full, cut = tmp_path / "full", tmp_path / "cut"
    collect(CollectConfig(ENV, episodes=4, seed=3), full, progress=False)
    # Interrupt a real run: kill the process once its first shard is on disk.
    proc = subprocess.Popen([sys.executable, "-m", "riskmap", "collect", "--env", ENV,
                             "--episodes", "4", "--seed", "3", "--out", str(cut), "--quiet"])
    deadline = time.time() + 120
    while not shard_path(cut, 0).exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done_before = len(list((cut / "shards").glob("*.npz")))
    assert done_before >= 1
    with pytest.raises(InputError, match="--resume"):
        collect(CollectConfig(ENV, episodes=4, seed=3), cut, progress=False)
    collect(CollectConfig(ENV, episodes=4, seed=3), cut, resume=True, progress=False)
    _assert_same_dataset(full, cut, 4)
    assert json.loads((cut / "manifest.json").read_text())["counts"]["episodes"] == 4


def test_resume_redoes_a_corrupt_shard_and_refuses_another_config(tmp_path):
    d = tmp_path / "d"
    collect(CollectConfig(ENV, episodes=2, seed=0), d, progress=False)
    good = _load(shard_path(d, 1))
    shard_path(d, 1).write_bytes(b"not a zip file")
    collect(CollectConfig(ENV, episodes=2, seed=0), d, resume=True, progress=False)
    np.testing.assert_array_equal(_load(shard_path(d, 1))["states"], good["states"])
    with pytest.raises(InputError, match="different configuration"):
        collect(CollectConfig(ENV, episodes=2, seed=9), d, resume=True, progress=False)


def test_bad_inputs(tmp_path):
    with pytest.raises(InputError, match="unknown env 'nope-v0'"):
        CollectConfig("nope-v0", episodes=1)
    with pytest.raises(InputError, match="--episodes"):
        CollectConfig(ENV, episodes=0)
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "file.txt").write_text("x")
    with pytest.raises(InputError, match="not a dataset directory"):
        collect(CollectConfig(ENV, episodes=1), tmp_path / "junk", progress=False)
