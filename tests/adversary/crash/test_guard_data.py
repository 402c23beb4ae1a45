"""Guard windows from attack records: cut at the adversary's collision, positives name it."""

import json

import numpy as np
import pytest

from adversary.cli import main as adversary_main
from adversary.crash.guard_data import GuardDataConfig, contact_onset, export, job_name, recorder_kinds
from adversary.crash.judge import box_iou, braking_track, judge, rollout
from adversary.crash.scenes import AttackScene, record_attack_scene, save_record
from rasterize.errors import InputError
from rasterize.scene import AgentKind
from rasterize.tracks import Tracks
from riskmap.guard.dataset import labels_for, load_frames, load_split
from riskmap.guard.features import MAX_HORIZON_S
from riskmap.infra.atomic import write_json
from riskmap.registry import cached_planner

# Episode 9 of highway-v0 seed 0: window row 3 drives ahead of the ego in the lane the ego keeps;
# braking hard in front of the played-back human it is rear-ended (tests/adversary/crash/test_judge_rollout.py).
SCENE, AHEAD = AttackScene("highway-v0", 0, 9), 3


def _attack(record, tracks, rows, adv_row, name):
    planner = cached_planner("replay")
    metrics = judge(record, tracks, rows, adv_row, planner, "replay")
    return {"name": name, "scene": {"env_id": SCENE.env_id, "scene_seed": SCENE.scene_seed,
                                    "episode": SCENE.episode, "t0_s": SCENE.t0_s, "horizon_s": SCENE.horizon_s},
            "planner": "replay", "selector": "manual", "status": "ok", "adversary_row": adv_row,
            "collision": metrics["collision"], "metrics": metrics, "tracks": tracks.tolist()}


@pytest.fixture(scope="module")
def attack_run(tmp_path_factory):
    """An attack run of two records of the same scene: the car ahead brakes hard (a collision)
    or gently (none), and one record without a candidate."""
    root = tmp_path_factory.mktemp("attack_run")
    record = record_attack_scene(SCENE)
    scenes = root / "scenes"
    for name in ("scene_00000", "scene_00001", "scene_00002"):
        save_record(record, scenes / f"{name}.npz")
    write_json(root / "run" / "run.json", {"planner": "replay", "scenes": str(scenes), "seed": 0,
                                           "config": {"selector": "manual"}})
    hard = braking_track(record, AHEAD, decel_mps2=8.0)[None]
    gentle = braking_track(record, AHEAD, decel_mps2=0.5)[None]
    crash, calm = _attack(record, hard, [AHEAD], AHEAD, "scene_00000"), _attack(record, gentle, [AHEAD], AHEAD,
                                                                                  "scene_00001")
    assert crash["collision"] and not calm["collision"] and not calm["metrics"]["collision_any"]
    write_json(root / "run" / "attacks" / "scene_00000.json", crash)
    write_json(root / "run" / "attacks" / "scene_00001.json", calm)
    write_json(root / "run" / "attacks" / "scene_00002.json", {"name": "scene_00002", "status": "no_candidate",
                                                               "collision": False})
    result = rollout(record, hard, [AHEAD], cached_planner("replay"), "replay")
    return root, record, crash, result


@pytest.mark.slow
def test_positive_windows_end_before_the_collision_and_name_the_adversary(attack_run, tmp_path):
    root, record, crash, result = attack_run
    summary = export([root / "run"], tmp_path, GuardDataConfig(split="adversarial"), progress=False)
    assert summary["records"] == 3 and summary["used"] == 2 and summary["skipped"] == {"no_candidate": 1}
    assert summary["splits"]["adversarial"]["crashes"] == 1 and summary["partner_is_adversary"] == 1
    assert summary["matches_attack"] == 2

    name = job_name("adversarial", "highway-v0", "replay", "manual", 0, "scene_00000")
    meta = json.loads((tmp_path / "jobs" / f"{name}.json").read_text())
    windows = dict(np.load(tmp_path / "jobs" / f"{name}.npz"))
    judged = round(crash["metrics"]["collision_time_s"] / result.dt_s)
    adversary = int(result.row_ids(record)[AHEAD])
    assert meta["collided"] and meta["judged_step"] == judged and meta["adversary_recorder_id"] == adversary
    # Cut at the first touch of the boxes that the judged collision (IoU > 0.02) belongs to.
    cut = meta["cut_step"]
    s, sz, ego = result.states, result.sizes, result.ego
    assert cut <= judged and all(box_iou(s[ego, k], sz[ego], s[adversary, k], sz[adversary]) > 0
                                 for k in range(cut, judged + 1))
    assert box_iou(s[ego, cut - 1], sz[ego], s[adversary, cut - 1], sz[adversary]) == 0.0
    assert "label" not in windows
    positive = labels_for(windows["ttc_s"], MAX_HORIZON_S) == 1
    # One positive window per 10 Hz step over the longest label horizon (3 s) before the
    # collision, none at it; each knows its time to contact: the steps to the cut.
    np.testing.assert_array_equal(np.sort(windows["last_step"][positive]),
                                  np.arange(cut - round(MAX_HORIZON_S / result.dt_s), cut))
    assert (windows["neighbour"][positive] == adversary).all()
    np.testing.assert_allclose(windows["ttc_s"][positive],
                               (cut - windows["last_step"][positive]) * result.dt_s, atol=1e-5)
    assert windows["last_step"].max() < cut           # nothing after the cut
    assert (~positive).sum() > 0
    assert (np.isinf(windows["ttc_s"]) | (windows["ttc_s"] > MAX_HORIZON_S) | positive).all()
    # decision frames every 0.5 s up to the cut
    assert windows["frames"].tolist() == [len(range(5, cut + 1, 5))]

    calm_name = job_name("adversarial", "highway-v0", "replay", "manual", 0, "scene_00001")
    calm = dict(np.load(tmp_path / "jobs" / f"{calm_name}.npz"))
    calm_meta = json.loads((tmp_path / "jobs" / f"{calm_name}.json").read_text())
    assert np.isinf(calm["ttc_s"]).all() and not calm_meta["collided"] and calm_meta["cut_step"] is None
    assert calm_meta["positives"] == 0 and meta["positives"] == positive.sum()
    # Not cut (the rollout runs the whole horizon): negatives every 0.5 s up to the last step
    # whose 3 s future lies inside the rollout.
    last_known = result.states.shape[1] - 1 - round(MAX_HORIZON_S / result.dt_s)
    assert calm["last_step"].max() == 5 * (last_known // 5)

    for horizon in (1.0, 2.0, 3.0):
        merged = load_split(tmp_path, "adversarial", horizon)
        assert len(merged["label"]) == len(windows["ttc_s"]) + len(calm["ttc_s"])
        assert merged["label"].sum() == round(horizon / result.dt_s)
    frames = load_frames(tmp_path, "adversarial")
    assert frames["frames"] == int(windows["frames"][0]) + int(calm["frames"][0])


@pytest.mark.slow
def test_val_fraction_sends_the_last_scenes_to_val_and_resume_is_required(attack_run, tmp_path):
    root = attack_run[0]
    config = GuardDataConfig(split="train", val_fraction=0.6)      # 2 of the 3 scenes
    summary = export([root / "run"], tmp_path, config, progress=False)
    assert summary["splits"]["train"] == {**summary["splits"]["train"], "episodes": 1, "crashes": 1}
    assert summary["splits"]["val"] == {**summary["splits"]["val"], "episodes": 1, "crashes": 0, "positives": 0}
    assert sorted(p.name.split("_adv_")[0] for p in (tmp_path / "jobs").glob("*.npz")) == ["train", "val"]
    with pytest.raises(InputError, match="--resume"):
        export([root / "run"], tmp_path, config, progress=False)
    again = export([root / "run"], tmp_path, config, resume=True, progress=False)
    assert again["splits"] == summary["splits"]


@pytest.mark.slow
def test_judge_cut_ends_the_windows_at_the_judged_collision(attack_run, tmp_path):
    root, _, crash, result = attack_run
    export([root / "run"], tmp_path, GuardDataConfig(cut="judge"), progress=False)
    name = job_name("adversarial", "highway-v0", "replay", "manual", 0, "scene_00000")
    meta = json.loads((tmp_path / "jobs" / f"{name}.json").read_text())
    windows = dict(np.load(tmp_path / "jobs" / f"{name}.npz"))
    assert meta["cut_step"] == meta["judged_step"] == round(crash["metrics"]["collision_time_s"] / result.dt_s)
    positive = labels_for(windows["ttc_s"], MAX_HORIZON_S) == 1
    assert windows["last_step"][positive].max() == meta["cut_step"] - 1
    assert windows["ttc_s"][positive].min() == pytest.approx(result.dt_s)


@pytest.mark.slow
def test_skip_scenes_leaves_the_first_scenes_of_the_run_out(attack_run, tmp_path):
    root = attack_run[0]
    summary = export([root / "run"], tmp_path, GuardDataConfig(skip_scenes=1), progress=False)
    # scene_00000 (the crash) is left out: scene_00001 is written, scene_00002 has no candidate
    assert summary["records"] == 2 and summary["used"] == 1 and summary["skipped"] == {"no_candidate": 1}
    assert summary["splits"]["adversarial"]["episodes"] == 1
    assert summary["splits"]["adversarial"]["crashes"] == summary["splits"]["adversarial"]["positives"] == 0
    written = sorted(p.stem for p in (tmp_path / "jobs").glob("*.npz"))
    assert written == [job_name("adversarial", "highway-v0", "replay", "manual", 0, "scene_00001")]
    assert summary["config"]["skip_scenes"] == 1
    # skipping more scenes than there are writes none; the shares of val count the kept scenes only
    assert export([root / "run"], tmp_path / "none", GuardDataConfig(skip_scenes=3), progress=False)["records"] == 0
    assert not list((tmp_path / "none" / "jobs").glob("*.npz"))
    val = export([root / "run"], tmp_path / "val", GuardDataConfig(split="train", skip_scenes=1, val_fraction=0.5),
                 progress=False)
    assert val["records"] == 2 and set(val["splits"]) == {"train"}       # scene_00002 (val) has no candidate
    with pytest.raises(InputError, match="--skip-scenes"):
        GuardDataConfig(skip_scenes=-1)


@pytest.mark.slow
def test_cli_skip_scenes(attack_run, tmp_path, capsys):
    root = attack_run[0]
    assert adversary_main(["guard-data", "--attacks", str(root / "run"), "--out", str(tmp_path / "g"),
                           "--skip-scenes", "1", "--quiet"]) == 0
    assert [p.name.rsplit("_", 1)[-1] for p in (tmp_path / "g" / "jobs").glob("*.npz")] == ["00001.npz"]
    summary = json.loads((tmp_path / "g" / "adversary_adversarial.json").read_text())
    assert summary["config"]["skip_scenes"] == 1 and summary["records"] == 2
    assert adversary_main(["guard-data", "--attacks", str(root / "run"), "--out", str(tmp_path / "h"),
                           "--skip-scenes", "-1", "--quiet"]) == 2
    assert "--skip-scenes" in capsys.readouterr().err
    assert not (tmp_path / "h").exists()


def test_contact_onset_walks_back_over_the_unbroken_overlap():
    # Ego (agent 0) at x = 0; agent 1 approaches from 10 m to overlapping, then stays; agent 2 far.
    xs = np.array([10.0, 7.0, 5.5, 4.0, 3.0, 3.0])
    states = np.zeros((3, len(xs), 6))
    states[..., 2] = 1.0
    states[1, :, 0] = xs
    states[2, :, 1] = 50.0
    valid = np.ones((3, len(xs)), bool)
    tracks = Tracks(states, valid, np.array([[5.0, 2.0]] * 3), np.zeros(3, np.int8))
    # Boxes 5 m long touch below 5 m between centres: overlap from step 3 (x = 4) on.
    assert contact_onset(tracks, 0, 5) == (3, 1)
    with pytest.raises(InputError):
        contact_onset(tracks, 0, 1)


@pytest.mark.slow
def test_cli_writes_the_split_and_rejects_bad_input(attack_run, tmp_path, capsys):
    root = attack_run[0]
    assert adversary_main(["guard-data", "--attacks", str(root / "run"), "--out", str(tmp_path / "g"),
                           "--quiet"]) == 0
    assert "adversarial: " in capsys.readouterr().out
    assert adversary_main(["guard-data", "--attacks", str(tmp_path), "--out", str(tmp_path / "h")]) == 2
    with pytest.raises(InputError):
        GuardDataConfig(split="train_x")


def test_recorder_kinds_follow_the_log_and_default_to_vehicles():
    log_kinds = np.array([int(AgentKind.VEHICLE), int(AgentKind.OBSTACLE)])
    kinds = recorder_kinds(log_kinds, np.array([1, -1, 0]))
    assert kinds.tolist() == [int(AgentKind.OBSTACLE), int(AgentKind.VEHICLE), int(AgentKind.VEHICLE)]
