"""Attack scenes from CommonRoad recordings: record, save/load, the judge's rollout, the sweep."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from adversary.cli import main
from adversary.crash.attack import AttackConfig
from adversary.crash.cli import default_models
from adversary.crash.judge import braking_track, ego_track_2hz, judge, rollout
from adversary.crash.recorded import record_recorded_scene, recording_family, recording_traffic
from adversary.crash.run import run_attacks
from adversary.crash.scene_sweep import RecordingSweep, record_scenes
from adversary.crash.scenes import RECORDED_ENV, AttackScene, load_record, save_record
from rasterize.errors import InputError
from riskmap.registry import cached_planner
from tests.adversary.conftest import exit_code

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"
RECORDING = FIXTURES / "USA_US101-4_1_T-1.xml"     # 10 s; 8 vehicles recorded over 0-8 s
TRAFFIC = "checkpoints/crash_traffic_us101"        # trained on recorded US-101 windows
EMPTY = np.zeros((0, 12, 6))


def _scene(ego_id: int, t0_s: float = 2.0) -> AttackScene:
    return AttackScene(RECORDED_ENV, 0, 0, t0_s, recording=str(RECORDING), ego_id=ego_id)


@pytest.fixture(scope="module")
def record():
    return record_recorded_scene(_scene(427))      # a slow car (2.5 m/s) 9 m behind another


def _row_ahead(record) -> int:
    """The nearest window row ahead of the ego in its lane at t0."""
    w = record.window
    ego = w.states[0, w.current_index]
    best, best_ahead = -1, np.inf
    for row in range(1, len(record.agent_ids)):
        d = w.states[row, w.current_index, :2] - ego[:2]
        ahead, lateral = d @ ego[2:4], d @ np.array([-ego[3], ego[2]])
        if 0 < ahead < best_ahead and abs(lateral) < 1.5:
            best, best_ahead = row, ahead
    return best


def test_recorded_record_round_trips_bit_identically(record, tmp_path):
    save_record(record, tmp_path / "scene.npz")
    loaded = load_record(tmp_path / "scene.npz")
    assert loaded.scene == record.scene and loaded.family == record.family == "us101"
    assert loaded.scene.recording == str(RECORDING) and loaded.scene.ego_id == 427
    for name in ("states", "valid", "sizes", "kinds"):
        assert np.array_equal(getattr(loaded.log, name), getattr(record.log, name))
        assert np.array_equal(getattr(loaded.window, name), getattr(record.window, name))
    assert np.array_equal(loaded.agent_ids, record.agent_ids)
    assert np.array_equal(loaded.window.route_xy, record.window.route_xy)
    assert len(loaded.window.lanes) == len(record.window.lanes) > 0
    for a, b in zip(loaded.window.lanes, record.window.lanes):
        assert np.array_equal(a.centre, b.centre) and np.array_equal(a.left, b.left)


def test_window_ego_row_is_the_recording_at_t0(record):
    traffic = recording_traffic(RECORDING)
    ego = traffic.index_of(427)
    assert record.log.ego_id == ego and record.agent_ids[0] == ego
    assert record.t0_step == 20 and record.log.num_steps == 81          # 0 .. t0 + 6 s at 10 Hz
    w = record.window
    assert np.array_equal(w.states[0, w.current_index], traffic.states[ego, 20])
    assert np.array_equal(w.states[0], traffic.states[ego, 0:81:5])      # 2 s past, 6 s future at 2 Hz
    assert len(record.agent_ids) >= 2 and w.route_xy is not None and w.route_xy.shape[1] == 2


def test_replay_with_untouched_log_reproduces_the_recording(record):
    planner = cached_planner("replay")
    result = rollout(record, EMPTY, [], planner, "replay")
    assert result.ego == record.log.ego_id and result.t0_step == record.t0_step
    assert result.states.shape == record.log.states.shape
    assert np.array_equal(result.states, record.log.states) and np.array_equal(result.valid, record.log.valid)
    assert np.array_equal(result.log_ids, np.arange(len(record.log.sizes)))
    assert not result.drive["off_road"] and not result.drive["collided"]
    metrics = judge(record, EMPTY, [], 1, planner, "replay", result=result)
    assert not metrics["collision"] and not metrics["collision_any"]


def test_idm_is_handed_over_at_t0(record):
    result = rollout(record, EMPTY, [], cached_planner("idm"), "idm", keep_scene=True)
    ego, k0 = result.ego, record.t0_step
    human = record.log.states[record.log.ego_id]
    assert np.array_equal(result.states[ego, :k0 + 1], human[:k0 + 1])   # the human's own past
    assert result.valid[ego].all() and result.states.shape[1] == 81
    assert not np.allclose(result.states[ego, k0 + 1:, :2], human[k0 + 1:, :2])   # then IDM drives
    assert np.linalg.norm(result.states[ego, k0 + 1, :2] - human[k0, :2]) < 1.0    # no jump at t0
    assert result.drive["driver"] == "RecordedRouteIdmPlanner" and result.drive["plan_calls"] == 12
    track = ego_track_2hz(result)
    assert np.array_equal(track[:5], record.window.states[0, :5])
    scene = result.final_scene
    assert scene.current_index == 80 and scene.ego_index == 0 and len(scene.lanes) > 0
    assert np.array_equal(scene.states[0], result.states[ego])


def test_car_ahead_braking_is_rear_ended_by_the_replayed_human(record):
    row = _row_ahead(record)
    assert row > 0
    tracks = braking_track(record, row)[None]
    planner = cached_planner("replay")
    result = rollout(record, tracks, [row], planner, "replay")
    metrics = judge(record, tracks, [row], row, planner, "replay", result=result)
    assert metrics["collision"] and metrics["collision_type"] == "ego rear-ends"
    assert metrics["collision_time_s"] > record.scene.t0_s and not metrics["adversary_off_road"]
    # the replayed human drove on through the contact: the rollout covers the whole horizon
    assert result.states.shape[1] == 81 and result.drive["collided"]


def test_recorded_scene_checks_and_refusals(tmp_path):
    with pytest.raises(InputError, match="recorded from 0.0 to 0.7 s"):
        record_recorded_scene(_scene(373))                       # leaves the recording early
    with pytest.raises(InputError, match="recording and an ego_id"):
        AttackScene(RECORDED_ENV, 0, 0).check(10)
    with pytest.raises(InputError, match="is not a dynamic obstacle"):
        record_recorded_scene(_scene(1))
    assert recording_family("x/USA_Lanker-2_3_T-1.xml") == "lankershim"
    with pytest.raises(InputError, match="--family"):
        recording_family("x/DEU_Town-1_1_T-1.xml")
    assert recording_family("x/DEU_Town-1_1_T-1.xml", "town") == "town"


def test_scenes_sweep_skips_with_reasons_resumes_and_dedups(tmp_path):
    inputs = tmp_path / "in"
    inputs.mkdir()
    shutil.copy(RECORDING, inputs / RECORDING.name)
    shutil.copy(RECORDING, inputs / "USA_US101-4_3_T-1.xml")     # the same traffic moment
    shutil.copy(FIXTURES / "USA_US101-3_3_T-1.xml", inputs / "USA_US101-3_3_T-1.xml")   # 3 s long
    out = tmp_path / "scenes"
    assert main(["scenes", "--commonroad", str(inputs), "--count", "2", "--out", str(out), "--quiet"]) == 0
    index = json.loads((out / "index.json").read_text())
    assert index["env_id"] == RECORDED_ENV and index["family"] == "us101" and len(index["scenes"]) == 2
    assert [Path(p).name for p in index["commonroad"]] == ["USA_US101-3_3_T-1.xml", RECORDING.name]
    assert index["files_left_out"] == [{"file": "USA_US101-4_3_T-1.xml", "why": f"same traffic as {RECORDING.name}"}]
    assert index["skipped"] and all(set(s) == {"file", "ego_id", "why"} for s in index["skipped"])
    assert any("the window needs" in s["why"] for s in index["skipped"])
    first = index["scenes"]
    assert main(["scenes", "--commonroad", str(inputs), "--count", "20", "--out", str(out), "--resume",
                 "--quiet"]) == 0
    index = json.loads((out / "index.json").read_text())
    assert index["scenes"][:2] == first and len(index["scenes"]) == 8          # every usable vehicle
    assert index["next_candidate"] == index["candidates"] == len(index["scenes"]) + len(index["skipped"])
    records = [load_record(out / f"{name}.npz") for name in index["scenes"]]
    keys = {(r.scene.scene_seed, r.scene.episode) for r in records}
    assert len(keys) == len(records)                                     # distinct attack seeds
    assert {r.scene.ego_id for r in records} == {400, 401, 405, 427, 442, 451, 468, 475}
    assert default_models(out, None, None) == (Path("checkpoints/crash_traffic_us101"),
                                               Path("checkpoints/crash_selector_us101"))
    with pytest.raises(InputError, match="other recordings"):
        record_scenes(RecordingSweep((str(RECORDING),)), 2, out, resume=True, progress=False)


def test_scenes_bad_input_is_one_line(tmp_path, capsys):
    text = tmp_path / "notes.txt"
    text.write_text("not a scenario")
    unknown = tmp_path / "DEU_Town-1_1_T-1.xml"
    shutil.copy(RECORDING, unknown)
    out = tmp_path / "out"
    cases = [(["--commonroad", str(text)], "not a CommonRoad .xml"),
             (["--commonroad", str(unknown)], "pass --family"),
             (["--env", "highway-v0", "--seed", "0", "--commonroad", str(RECORDING)], "not allowed with")]
    for args, expected in cases:
        assert exit_code(["scenes", *args, "--count", "1", "--out", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert expected in err[-1] and err[-1].startswith("adversary scenes: error:"), err
        assert "Traceback" not in "\n".join(err) and not out.exists()


def test_attack_runs_on_recorded_scenes(tmp_path):
    scenes = tmp_path / "scenes"
    record_scenes(RecordingSweep((str(RECORDING),)), 1, scenes, progress=False)
    config = AttackConfig(selector="nearest", iterations_closed_loop=4, replan_every=2)
    # A traffic model of another family is refused before any work, in one line naming the fix.
    with pytest.raises(InputError, match="trained on highway windows.*crash_traffic_us101"):
        run_attacks("idm", scenes, 1, config, 0, tmp_path / "wrong", "checkpoints/crash_traffic_highway", None,
                    progress=False)
    assert not (tmp_path / "wrong").exists()
    summary = run_attacks("idm", scenes, 1, config, 0, tmp_path / "attack", TRAFFIC, None, progress=False)
    [path] = (tmp_path / "attack" / "attacks").glob("*.json")
    result = json.loads(path.read_text())
    assert result["status"] == "ok", result.get("error")
    assert result["timing"]["rollouts"] >= 3 and result["scene"]["recording"] == str(RECORDING)
    assert summary["summary"]["scenes"] == 1
