"""`riskmap collect --from-commonroad`: recorded vehicles as demonstrators, in the usual dataset format."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("commonroad")

from rasterize.errors import InputError
from riskmap.cli import main
from riskmap.data.collect_commonroad import collect_commonroad
from riskmap.data.dataset import DemoDataset

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("commonroad") / "data"
    assert main(["collect", "--from-commonroad", str(FIXTURES), "--out", str(out), "--quiet"]) == 0
    return out


def test_every_vehicle_with_history_and_future_is_a_demonstrator(recorded):
    manifest = json.loads((recorded / "manifest.json").read_text())
    # US101-3_3 lasts 3.1 s: nobody has 2 s + 6 s. In US101-4_1 (10 s) five vehicles are recorded
    # 0-10 s (windows at 2, 3, 4 s) and three leave between 8.3 and 8.7 s (one window at 2 s).
    assert manifest["counts"] == {"episodes": 8, "windows": 18, "ego_crashes": 0,
                                  "ego_off_network": 0, "simulated_s": pytest.approx(75.4)}
    infos = []
    for shard in sorted((recorded / "shards").glob("*.npz")):
        with np.load(shard) as data:
            infos.append(json.loads(bytes(data["episode_info"]).decode()))
    assert [i["vehicle_id"] for i in infos] == [400, 401, 405, 427, 442, 451, 468, 475]
    assert {i["file"] for i in infos} == {"USA_US101-4_1_T-1.xml"}
    assert [i["time_steps"] for i in infos][-1] == [20, 30, 40]


def test_windows_carry_no_nan_and_load_as_training_samples(recorded):
    dataset = DemoDataset(recorded)
    assert len(dataset) == 18 and dataset.source == "commonroad"
    for i in range(len(dataset)):
        scene = dataset.scene(i)
        assert scene.valid[scene.ego_index].all()              # full history and future
        assert np.isfinite(scene.states[scene.valid]).all() and scene.route_xy is not None
        sample = dataset[i]
        for key, value in sample.items():
            assert bool(value.isfinite().all()) if value.is_floating_point() else True, key
        assert sample["raster"].sum() > 0 and sample["future"].shape == (12, 2)


def test_resume_rewrites_only_missing_shards(recorded, tmp_path):
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-r", str(recorded), str(copy)], check=True)
    shard = copy / "shards" / "episode_000003.npz"
    kept = copy / "shards" / "episode_000000.npz"
    kept_mtime = kept.stat().st_mtime_ns
    shard.unlink()
    manifest = collect_commonroad([FIXTURES], copy, resume=True, progress=False)
    assert manifest["counts"]["windows"] == 18
    assert kept.stat().st_mtime_ns == kept_mtime                 # finished shards are kept
    with np.load(shard) as a, np.load(recorded / "shards" / "episode_000003.npz") as b:
        assert set(a.files) == set(b.files)
        for key in a.files:                                    # and the missing one is rebuilt
            np.testing.assert_array_equal(a[key], b[key])
    with pytest.raises(InputError, match="already holds a dataset"):
        collect_commonroad([FIXTURES], copy, progress=False)
    with pytest.raises(InputError, match="different configuration"):
        collect_commonroad([FIXTURES / "USA_US101-4_1_T-1.xml"], copy, resume=True, progress=False)


@pytest.mark.parametrize("inputs, words", [
    ([str(FIXTURES / "missing_dir")], "does not exist"),
    ([str(FIXTURES / "USA_US101-3_3_T-1.xml")], "no recorded vehicle"),
])
def test_bad_input_is_one_line_and_leaves_nothing(tmp_path, inputs, words):
    out = tmp_path / "never"
    result = subprocess.run([sys.executable, "-m", "riskmap", "collect", "--from-commonroad",
                             *inputs, "--out", str(out), "--quiet"], capture_output=True, text=True,
                            timeout=120, check=False, cwd=FIXTURES.parents[2])
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0]
    assert not out.exists()


def test_collect_without_a_source_names_the_fix(tmp_path, capsys):
    assert main(["collect", "--out", str(tmp_path / "x")]) == 2
    assert "--env ENV and --episodes N" in capsys.readouterr().err


def test_recorded_and_simulated_sources_do_not_mix(tmp_path, capsys):
    assert main(["collect", "--from-commonroad", str(FIXTURES), "--env", "highway-v0",
                 "--out", str(tmp_path / "x")]) == 2
    assert "not both" in capsys.readouterr().err and not (tmp_path / "x").exists()
