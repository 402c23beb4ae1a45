"""Urban recordings in `riskmap collect --from-commonroad`: groups by moment of traffic within a
configuration number, the recordings' family, and a synthetic signalised recording collected."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("commonroad")

import riskmap.data.collect_commonroad as collect_module
from riskmap.data.collect_commonroad import (
    CommonRoadCollectConfig,
    collect_commonroad,
    recorded_family,
    traffic_groups,
)


def _traffic(*ids: int, tags=(), lights=()) -> SimpleNamespace:
    obstacles = [SimpleNamespace(obstacle_id=i) for i in ids]
    return SimpleNamespace(scenario=SimpleNamespace(dynamic_obstacles=obstacles, tags=set(tags)),
                           lights=tuple(lights))


def test_files_of_one_configuration_sharing_vehicles_are_one_group():
    # US-101: the files of a configuration are one moment (they share vehicles): its name.
    us101 = {Path("USA_US101-4_1_T-1.xml"): _traffic(1, 2, 3),
             Path("USA_US101-4_2_T-1.xml"): _traffic(2, 3, 4),
             Path("USA_US101-5_1_T-1.xml"): _traffic(1, 2, 3)}      # another configuration by name
    assert set(traffic_groups(us101).values()) == {"USA_US101-4", "USA_US101-5"}
    # Lankershim: configuration 2 is a map with several moments; each is a group.
    lanker = {Path("USA_Lanker-2_1_T-1.xml"): _traffic(10, 11),
              Path("USA_Lanker-2_3_T-1.xml"): _traffic(11, 12),
              Path("USA_Lanker-2_10_T-1.xml"): _traffic(20, 21),
              Path("USA_Lanker-2_2_T-1.xml"): _traffic(21, 22),
              Path("USA_Lanker-2_15_T-1.xml"): _traffic(30)}
    groups = traffic_groups(lanker)
    assert groups[Path("USA_Lanker-2_1_T-1.xml")] == groups[Path("USA_Lanker-2_3_T-1.xml")] == "USA_Lanker-2_1+3"
    assert groups[Path("USA_Lanker-2_10_T-1.xml")] == "USA_Lanker-2_2+10"
    assert groups[Path("USA_Lanker-2_15_T-1.xml")] == "USA_Lanker-2_15"
    assert traffic_groups({Path("my_scene.xml"): _traffic(1)}) == {Path("my_scene.xml"): "my_scene"}


def test_the_family_is_the_recordings():
    assert recorded_family({Path("a.xml"): _traffic(1, tags=("highway",))}) == "highway"
    assert recorded_family({Path("a.xml"): _traffic(1, tags=("urban",))}) == "urban"
    assert recorded_family({Path("a.xml"): _traffic(1, lights=("a light",))}) == "urban"
    assert CommonRoadCollectConfig(files=(), family="urban").raster.extent.left_m == 45.0
    with pytest.raises(Exception, match="unknown for recordings"):
        CommonRoadCollectConfig(files=(), family="roundabout")


def test_a_signalised_recording_collects_as_urban_with_held_goals(tmp_path, monkeypatch):
    from tests.rasterize.signal_scenario import signal_scenario

    folder = tmp_path / "recordings"
    folder.mkdir()
    (folder / "USA_Synth-1_1_T-1.xml").write_text("<commonRoad/>")     # read by the stub below
    monkeypatch.setattr(collect_module, "load_scenario", lambda path: signal_scenario())
    manifest = collect_commonroad([folder], tmp_path / "data", progress=False)
    assert manifest["config"]["family"] == "urban" and manifest["groups"] == ["USA_Synth-1"]
    assert manifest["counts"]["episodes"] == 3
    # Vehicle 100 (9 m/s) meets a red light: at 2 s (x = -27) its route goal is held before the
    # stop line (x = -2) although 6 s at its speed would take it 54 m on.
    infos = []
    for shard in sorted((tmp_path / "data" / "shards").glob("*.npz")):
        with np.load(shard) as data:
            infos.append(json.loads(bytes(data["episode_info"]).decode()))
    first = next(i for i in infos if i["vehicle_id"] == 100)
    assert first["time_steps"][0] == 20
    along, _ = first["goal_error_m"][0]
    # The human crossed on red and drove on to x = 27: the held goal (x <= -4) is > 30 m short.
    assert along > 30.0
