"""Both kinds of stored attack scene go through the one `rollout`, each in the world its source
builds, and drive exactly as the two rollouts did before they were one (issue 41).

The digests were taken with the code before the change (judge.rollout's highway-env branch and
the former adversary.crash.recorded.rollout_recorded) on the same scenes, tracks and planners; the rollout
must reproduce them. They cover every array the `Rollout` holds, its drive record (but the plan
times, which are wall-clock) and the kept final scene and windows."""

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from adversary.crash.highway_source import HighwaySource
from adversary.crash.judge import braking_track, rollout
from adversary.crash.recorded import record_recorded_scene
from adversary.crash.recorded_source import RecordedSource
from adversary.crash.scene_source import scene_source
from adversary.crash.scenes import RECORDED_ENV, AttackScene, record_attack_scene
from riskmap.registry import cached_planner

RECORDING = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad" / "USA_US101-4_1_T-1.xml"
HIGHWAY = AttackScene("highway-v0", 0, 9)            # row 3 drives ahead of the ego
RECORDED = AttackScene(RECORDED_ENV, 0, 0, 2.0, recording=str(RECORDING), ego_id=427)
WINDOW_STEPS = (30, 60)                               # 10 Hz steps cut into training windows

# sha256 (first 16 hex digits) of `_digest` with the code before the change.
BEFORE = {
    ("highway", "cv"): "a1bf73af58f6678c",
    ("recorded", "cv"): "ad8aa82aa71670f4",
    ("recorded", "idm"): "c7d2d971bf989377",
}


def _array(a) -> bytes:
    a = np.asarray(a)
    if a.dtype.kind == "f":        # 6 decimals: the same on every platform, far below any change
        a = np.round(a.astype(np.float64), 6) + 0.0
    return a.tobytes() + str(a.shape).encode()


def _scene_bytes(scene) -> bytes:
    route = b"" if scene.route_xy is None else _array(scene.route_xy)
    return _array(scene.states) + _array(scene.valid) + _array(scene.sizes) + route


def _digest(result) -> str:
    drive = {k: v for k, v in result.drive.items() if not k.startswith("plan_ms")}
    parts = [_array(result.states), _array(result.valid), _array(result.sizes), _array(result.log_ids),
             f"{result.ego} {result.t0_step} {result.dt_s} {result.planner_spec}".encode(),
             json.dumps(drive, sort_keys=True, default=str).encode(), _scene_bytes(result.final_scene)]
    parts += [_scene_bytes(window) for window in result.scenes]
    return hashlib.sha256(b"|".join(parts)).hexdigest()[:16]


@pytest.fixture(scope="module")
def records():
    return {"highway": record_attack_scene(HIGHWAY), "recorded": record_recorded_scene(RECORDED)}


def _drive(record, spec: str):
    row = 1 if record.scene.recording else 3
    tracks = braking_track(record, row, decel_mps2=6.0)[None]
    return rollout(record, tracks, [row], cached_planner(spec), spec, keep_scene=True, scene_steps=WINDOW_STEPS)


def test_each_kind_has_its_source(records):
    assert isinstance(scene_source(records["highway"].scene), HighwaySource)
    assert isinstance(scene_source(records["recorded"].scene), RecordedSource)


@pytest.mark.parametrize("kind, spec", sorted(BEFORE))
def test_rollout_drives_as_before(records, kind, spec):
    result = _drive(records[kind], spec)
    assert len(result.scenes) == len(WINDOW_STEPS) and result.final_scene is not None
    assert _digest(result) == BEFORE[(kind, spec)]
