"""Recorded demonstrations as a training set: one demonstrator per recorded track, groups by
traffic configuration, smoothed tracks, bad tracks left out, settings derived from the data."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("commonroad")

from rasterize.commonroad import RecordedTraffic, load_scenario, smooth_track
from rasterize.config import Extent
from rasterize.errors import InputError
from riskmap.data.collect_commonroad import (
    ROUTE_ACCELS_MPS2,
    collect_commonroad,
    derived_extent,
    recording_group,
)
from riskmap.data.dataset import DemoDataset
from riskmap.training.train import resolve_goal_variance, split_episodes

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"
RECORDING = FIXTURES / "USA_US101-4_1_T-1.xml"


def _copies(tmp_path: Path, *names: str) -> Path:
    folder = tmp_path / "recordings"
    folder.mkdir()
    for name in names:
        shutil.copy(RECORDING, folder / name)
    return folder


@pytest.fixture(scope="module")
def two_configurations(tmp_path_factory) -> Path:
    """Configuration 4 in two files (the same traffic twice) and a copy posing as configuration 5."""
    root = tmp_path_factory.mktemp("recorded")
    folder = _copies(root, "USA_US101-4_1_T-1.xml", "USA_US101-4_2_T-1.xml", "USA_US101-5_1_T-1.xml")
    out = root / "data"
    collect_commonroad([folder], out, progress=False)
    return out


def test_recording_group_is_site_and_configuration():
    assert recording_group(Path("USA_US101-10_3_T-1.xml")) == ("USA_US101", "USA_US101-10")
    assert recording_group(Path("USA_Lanker-2_14_T-1.xml")) == ("USA_Lanker", "USA_Lanker-2")
    assert recording_group(Path("my_scene.xml")) == ("my_scene", "my_scene")


def test_a_track_in_several_files_of_one_configuration_is_one_demonstrator(two_configurations):
    manifest = json.loads((two_configurations / "manifest.json").read_text())
    # 8 demonstrators in the fixture: once for configuration 4 (its second file is skipped as
    # duplicates) and once for "configuration 5", which is another moment of traffic by name.
    assert manifest["counts"]["episodes"] == 16 and manifest["counts"]["windows"] == 36
    assert manifest["skipped"]["duplicate_tracks"] == 8
    assert manifest["groups"] == ["USA_US101-4", "USA_US101-5"]
    index = json.loads((two_configurations / "index.json").read_text())
    assert [s["group"] for s in index["shards"]] == ["USA_US101-4"] * 8 + ["USA_US101-5"] * 8


def test_validation_holds_out_whole_configurations(two_configurations):
    dataset = DemoDataset(two_configurations)
    train, val = split_episodes(dataset, 0.15, ("5",))
    assert {dataset.group_of(i) for i in train} == {"USA_US101-4"}
    assert {dataset.group_of(i) for i in val} == {"USA_US101-5"}
    assert sorted(train + val) == list(range(len(dataset)))
    train, val = split_episodes(dataset, 0.15)               # default: the last group
    assert {dataset.group_of(i) for i in val} == {"USA_US101-5"}
    with pytest.raises(InputError, match="no such group"):
        split_episodes(dataset, 0.15, ("7",))
    with pytest.raises(InputError, match="every group"):
        split_episodes(dataset, 0.15, ("4", "5"))


def test_settings_derived_from_the_recordings_are_in_the_manifest(two_configurations):
    manifest = json.loads((two_configurations / "manifest.json").read_text())
    derived, config = manifest["derived"], manifest["config"]
    how = derived["derivation"]
    assert derived["extent"] == config["raster"]["extent"]
    assert derived["extent"] == {k: float(v) for k, v in
                                 vars(derived_extent(np.array([how["forward_6s_max_m"]]),
                                                     np.array([how["lateral_max_m"]]))).items()}
    assert config["speed_limit_mps"] == derived["speed_limit_mps"] == \
        0.5 * np.ceil(2 * how["speed_p99_mps"])
    errors = {float(k): v for k, v in how["route_goal_error_m_by_accel"].items()}
    assert set(errors) == set(map(float, ROUTE_ACCELS_MPS2))
    assert config["route_accel_mps2"] == min(errors, key=errors.get)
    assert derived["goal_error_rms_m"]["along"] > derived["goal_error_rms_m"]["across"] > 0


def test_derived_extent_rule():
    assert derived_extent(np.array([50.0, 129.6]), np.array([1.0, 8.2])) == \
        Extent(front_m=150.0, back_m=30.0, left_m=15.0, right_m=15.0)
    assert derived_extent(np.array([20.0]), np.array([0.5])) == \
        Extent(front_m=30.0, back_m=10.0, left_m=10.0, right_m=10.0)


def test_goal_variance_comes_from_the_goal_error_in_cells(two_configurations):
    dataset = DemoDataset(two_configurations)
    rms = dataset.derived["goal_error_rms_m"]
    grid = dataset.grid
    expected = 0.5 * ((rms["along"] / grid.row_m) ** 2 + (rms["across"] / grid.col_m) ** 2)
    assert resolve_goal_variance(None, dataset) == pytest.approx(expected, abs=1e-3)
    assert resolve_goal_variance(2.0, dataset) == 2.0


def test_mixed_sites_are_refused_before_anything_is_written(tmp_path):
    folder = _copies(tmp_path, "USA_US101-4_1_T-1.xml", "USA_Lanker-1_1_T-1.xml")
    with pytest.raises(InputError, match=r"mixes recordings of several sites: USA_Lanker \(1 files\)"):
        collect_commonroad([folder], tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()


def test_smoothing_keeps_a_quadratic_track_and_removes_noise():
    dt = 0.1
    t = np.arange(80) * dt
    x = 3.0 + 12.0 * t + 0.4 * t ** 2                 # accelerating straight along x
    states = np.column_stack([x, np.full_like(t, -2.0), np.ones_like(t), np.zeros_like(t),
                              12.0 + 0.8 * t, np.zeros_like(t)])
    smooth = smooth_track(states, dt, 1.5)
    np.testing.assert_allclose(smooth[:, :2], states[:, :2], atol=1e-9)
    np.testing.assert_allclose(smooth[:, 4], 12.0 + 0.8 * t, atol=1e-9)   # speed = d position / dt
    noisy = states.copy()
    noisy[:, :2] += np.random.default_rng(0).normal(0.0, 0.3, (80, 2))
    cleaned = smooth_track(noisy, dt, 1.5)
    assert np.abs(cleaned[:, :2] - states[:, :2]).mean() < 0.6 * np.abs(noisy[:, :2] - states[:, :2]).mean()
    assert smooth_track(states[:3], dt, 1.5) is not None          # short tracks pass unchanged


def _with_state_changed(tmp_path: Path, obstacle: int, change) -> Path:
    """A copy of the fixture where the first trajectory point of `obstacle` is edited."""
    text = RECORDING.read_text()
    start = text.index(f'<dynamicObstacle id="{obstacle}">')
    at = text.index("<trajectory>", start)
    x_open = text.index("<x>", at) + 3
    x_close = text.index("</x>", x_open)
    path = tmp_path / RECORDING.name
    path.write_text(text[:x_open] + change(text[x_open:x_close]) + text[x_close:])
    return path


@pytest.mark.parametrize("change, reason", [
    (lambda x: "nan", "non-finite position"),
    (lambda x: str(float(x) + 40.0), "jump of"),
])
def test_tracks_that_are_not_finite_or_jump_are_left_out(tmp_path, change, reason):
    path = _with_state_changed(tmp_path, 373, change)
    traffic = RecordedTraffic(load_scenario(path), path.stem)
    assert 373 not in traffic.ids and re.match(reason, traffic.rejected[373])
    assert np.isfinite(traffic.states).all()
    clean = RecordedTraffic(load_scenario(RECORDING), RECORDING.stem)
    assert len(traffic.ids) == len(clean.ids) - 1 and not clean.rejected


def _set_based_copy(folder: Path) -> Path:
    """The fixture with every velocity an interval, as in a set-based (_S-1) scenario."""
    text = re.sub(r"<velocity>\s*<exact>([^<]*)</exact>\s*</velocity>",
                  r"<velocity><intervalStart>\1</intervalStart><intervalEnd>\1</intervalEnd></velocity>",
                  RECORDING.read_text())
    path = folder / "USA_US101-4_1_S-1.xml"
    path.write_text(text)
    return path


def test_a_set_based_file_is_one_line_and_skipped_beside_trajectory_files(tmp_path):
    folder = _copies(tmp_path, "USA_US101-4_1_T-1.xml")
    set_based = _set_based_copy(folder)
    with pytest.raises(InputError, match=r"set-based .*pass the trajectory files \(_T-1\)"):
        collect_commonroad([set_based], tmp_path / "alone", progress=False)
    assert not (tmp_path / "alone").exists()
    manifest = collect_commonroad([folder], tmp_path / "both", progress=False)
    assert manifest["skipped"]["set_based_files"] == 1 and manifest["counts"]["episodes"] == 8
