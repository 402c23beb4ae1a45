"""The fixtures read the same under every supported commonroad-io release.

`commonroad_readings.json` holds checksums of what the toolkit makes of the two NGSIM fixtures:
the recorded tracks, the lanes, and the scenes and BEV rasters of their first vehicles. They were
computed under commonroad-io 2026.1, and 2024.3 gave the same arrays bit for bit;
`make test-commonroad-oldest` runs this file under 2024.3. After a deliberate change to the
adapter or the rasteriser, rewrite the file with
`.venv/bin/python tests/rasterize/test_commonroad_readings.py`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("commonroad")

from rasterize.commonroad import RecordedTraffic, lanes_from_lanelets, load_scenario
from rasterize.config import raster_config_for_env
from rasterize.raster import rasterize_scene

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "commonroad"
NAMES = ("USA_US101-3_3_T-1", "USA_US101-4_1_T-1")
EXPECTED = Path(__file__).with_name("commonroad_readings.json")
SCENES = 3                   # scenes (and rasters) checked per file: its first vehicles
RTOL = 1e-10                 # room for a different summation order only


def _checksum(values) -> list[float]:
    """(sum, position-weighted sum): a reordering or a changed value alters the second."""
    flat = np.nan_to_num(np.asarray(values, dtype=np.float64).ravel(), nan=-7.0)
    return [float(flat.sum()), float(flat @ (np.arange(flat.size) % 97 + 1))]


def readings(name: str) -> dict:
    """Counts, ids and checksums of what the toolkit reads from fixture `name`."""
    scenario = load_scenario(FIXTURES / f"{name}.xml")
    traffic = RecordedTraffic(scenario, name)
    lanes = lanes_from_lanelets(scenario.lanelet_network)
    out = {
        "agents": len(traffic.ids), "steps": traffic.num_steps, "ids": traffic.ids.tolist(),
        "rejected": {str(k): v for k, v in sorted(traffic.rejected.items())},
        "valid": int(traffic.valid.sum()), "kinds": traffic.kinds.tolist(),
        "states": _checksum(traffic.states), "sizes": _checksum(traffic.sizes),
        "lanes": len(lanes), "line_types": [[int(lane.left_line), int(lane.right_line)] for lane in lanes],
        "lane_points": _checksum(np.concatenate([np.concatenate([lane.centre, lane.left, lane.right]).ravel()
                                                 for lane in lanes])),
        "lane_widths": _checksum([lane.width_m for lane in lanes]),
        "scenes": [],
    }
    raster = raster_config_for_env("highway-v0")
    for agent in range(len(traffic.ids)):
        steps = np.flatnonzero(traffic.valid[agent])
        if len(out["scenes"]) == SCENES:
            break
        if len(steps) < 25 or not traffic.is_vehicle[agent]:
            continue
        scene = traffic.scene(agent, int(steps[20]))
        image = rasterize_scene(scene, raster)
        out["scenes"].append({
            "ego": int(traffic.ids[agent]), "time_step": int(steps[20]), "agents": scene.num_agents,
            "states": _checksum(scene.states), "valid": int(scene.valid.sum()),
            "route": _checksum(scene.route_xy if scene.route_xy is not None else []),
            "raster": [int(channel.sum()) for channel in image],
            "raster_weighted": [int(channel.ravel().astype(np.int64) @ (np.arange(channel.size) % 97 + 1))
                                for channel in image],
        })
    return out


def _compare(got, want, where: str) -> None:
    if isinstance(want, dict):
        assert set(got) == set(want), where
        for key in want:
            _compare(got[key], want[key], f"{where}.{key}")
    elif isinstance(want, list):
        assert len(got) == len(want), where
        for i, (g, w) in enumerate(zip(got, want)):
            _compare(g, w, f"{where}[{i}]")
    elif isinstance(want, float):
        assert got == pytest.approx(want, rel=RTOL, abs=1e-9), where
    else:
        assert got == want, where


@pytest.mark.parametrize("name", NAMES)
def test_fixture_reads_as_recorded(name):
    expected = json.loads(EXPECTED.read_text())
    _compare(readings(name), expected[name], name)


if __name__ == "__main__":
    EXPECTED.write_text(json.dumps({name: readings(name) for name in NAMES}, indent=1) + "\n")
    print(f"wrote {EXPECTED}", file=sys.stderr)
