"""The hardening loop's parts: collision-free alternatives, attack windows, the mixed data, the CLI."""

import itertools
import json
import math

import numpy as np
import pytest

from adversary.cli import main as adversary_main
from adversary.crash.judge import box_iou, braking_track, judge, splice_tracks
from adversary.crash.scenes import AttackScene, record_attack_scene
from adversary.harden.dataset import ADVERSARIAL_GROUP, write_attack_shard, write_round_dataset
from adversary.harden.loop import HardenConfig, round_sidecar
from adversary.harden.windows import attacked_drive, hardening_windows
from rasterize.errors import InputError
from rasterize.tracks import Tracks
from riskmap.data.dataset import DemoDataset
from riskmap.registry import cached_planner
from riskmap.sim.records.alternatives import (
    alternative_track,
    first_clear_alternative,
    safest_clear_alternative,
)

DT = 0.1


def _straight(speed_mps: float, steps: int) -> np.ndarray:
    """An ego [steps, 6] driving along +x at a constant speed."""
    t = DT * np.arange(steps)
    return np.column_stack([speed_mps * t, np.zeros(steps), np.ones(steps), np.zeros(steps),
                            np.full(steps, speed_mps), np.zeros(steps)])


def test_alternative_track_keeps_the_path_and_blends_the_offset_in():
    states = _straight(10.0, 60)[None]
    valid = np.ones((1, 60), bool)
    same = alternative_track(states, valid, 0, 0, 59, DT, 0.0)
    np.testing.assert_allclose(same[:, :5], states[0, 1:, :5], atol=1e-9)
    braking = alternative_track(states, valid, 0, 0, 59, DT, -4.0)
    assert braking[-1, 4] == 0.0 and braking[-1, 0] == pytest.approx(10.0 ** 2 / 8.0, abs=0.3)
    shifted = alternative_track(states, valid, 0, 0, 59, DT, 0.0, offset_m=3.5, blend_s=2.0)
    assert shifted[-1, 1] == pytest.approx(3.5) and shifted[5, 3] > 0      # turned left while moving over
    np.testing.assert_allclose(shifted[-1, 2:4], [1.0, 0.0], atol=1e-9)   # and straight again after


def test_the_human_fallback_goes_on_along_its_own_heading():
    from adversary.harden.windows import constant_velocity

    heading = np.array([np.cos(2.0), np.sin(2.0)])
    ahead = constant_velocity(np.array([5.0, 1.0, *heading, 8.0, 0.3]), 10, DT)
    np.testing.assert_allclose(ahead[-1, :2], [5.0, 1.0] + 8.0 * 1.0 * heading)
    np.testing.assert_allclose(ahead[:, 2:5], np.tile([*heading, 8.0], (10, 1)))
    assert (ahead[:, 5] == 0).all()


def test_first_clear_alternative_tries_the_mildest_first():
    ego = _straight(10.0, 61)
    stopped = np.tile([40.0, 0.0, 1.0, 0.0, 0.0, 0.0], (61, 1))   # a car standing 40 m ahead
    tracks = Tracks(np.stack([stopped, ego]), np.ones((2, 61), bool), np.array([[5.0, 2.0], [5.0, 2.0]]),
                    np.zeros(2, np.int8))
    assert first_clear_alternative(tracks, 1, 0, 60, DT, (0.0, 1.0)) is None
    # -2 m/s² stops the ego 25 m on, short of the car; -4 too, but -2 is tried first
    assert first_clear_alternative(tracks, 1, 0, 60, DT, (0.0, -2.0, -4.0)) == (-2.0, 0.0)
    with pytest.raises(ValueError, match="on_road"):
        first_clear_alternative(tracks, 1, 0, 60, DT, (0.0,), (3.5,))
    # the safest keeps the most room: the hardest braking stops furthest from the car
    assert safest_clear_alternative(tracks, 1, 0, 60, DT, (0.0, -2.0, -4.0)) == (-4.0, 0.0)
    assert safest_clear_alternative(tracks, 1, 0, 60, DT, (0.0, 1.0)) is None


def test_the_safest_alternative_weighs_the_car_behind_too():
    ego = _straight(10.0, 61)
    ahead = np.tile([40.0, 0.0, 1.0, 0.0, 0.0, 0.0], (61, 1))
    behind = _straight(10.0, 61) - [12.0, 0, 0, 0, 0, 0]     # follows at 12 m, never brakes
    tracks = Tracks(np.stack([ahead, behind, ego]), np.ones((3, 61), bool), np.full((3, 2), [5.0, 2.0]),
                    np.zeros(3, np.int8))
    # -4 m/s² would be rear-ended by the follower; -2 stops in time ahead but is hit as well:
    # nothing along the path is clear, a lane change is (on an endless road)
    assert safest_clear_alternative(tracks, 2, 0, 60, DT, (-2.0, -4.0)) is None
    found = safest_clear_alternative(tracks, 2, 0, 60, DT, (0.0, -2.0), (3.5, -3.5),
                                     on_road=lambda *_: True)
    assert found is not None and found[1] in (3.5, -3.5)


# Episode 9 of highway-v0 seed 0: window row 3 drives ahead of the ego; braking hard in front of
# the played-back human it is rear-ended (tests/adversary/crash/test_guard_data.py).
SCENE, AHEAD = AttackScene("highway-v0", 0, 9), 3


@pytest.fixture(scope="module")
def rear_ended():
    record = record_attack_scene(SCENE)
    tracks = braking_track(record, AHEAD, decel_mps2=8.0)[None]
    metrics = judge(record, tracks, [AHEAD], AHEAD, cached_planner("replay"), "replay")
    assert metrics["collision"]
    attack = {"name": "scene_00009", "status": "ok", "collision": True, "adversary_row": AHEAD,
              "metrics": metrics, "tracks": tracks.tolist()}
    return record, attack


@pytest.fixture(scope="module")
def natural_and_windows(rear_ended, tmp_path_factory):
    """(natural highway dataset of 4 episodes, the rear-ended attack's windows): what a round mixes."""
    from riskmap.data.collect import CollectConfig, collect

    record, attack = rear_ended
    natural = tmp_path_factory.mktemp("harden") / "natural"
    collect(CollectConfig("highway-v0", episodes=4, seed=11), natural, progress=False)
    return natural, hardening_windows(record, attack, cached_planner("replay"), "replay")


@pytest.mark.slow
def test_attack_windows_avoid_the_adversary_with_a_full_future(rear_ended):
    record, attack = rear_ended
    made = hardening_windows(record, attack, cached_planner("replay"), "replay")
    info = made.info
    assert info["demonstration"] == "alternative" and len(made.scenes) == info["windows"] >= 5
    assert info["collision_step"] - 5 < info["steps"][-1] <= info["collision_step"] and info["steps"][0] < info["start_step"]
    log = splice_tracks(record, np.asarray(attack["tracks"]), [AHEAD])
    adversary = int(record.agent_ids[AHEAD])
    for scene, step in zip(made.scenes, info["steps"]):
        now = scene.current_index
        assert scene.valid[0, now:].all() and scene.states.shape[1] == now + 13     # 6 s ahead at 2 Hz
        assert scene.time_s == pytest.approx(step * DT)
        for j in range(1, 13):               # the demonstrated future never touches the adversary
            k = step + 5 * j
            if k < log.num_steps:
                assert box_iou(scene.states[0, now + j], scene.sizes[0], log.states[adversary, k],
                               log.sizes[adversary]) == 0.0
    # The attacked drive (the human braking too late) did collide where the windows now avoid it.
    assert attack["metrics"]["collision_time_s"] == pytest.approx(info["collision_step"] * DT)


@pytest.mark.slow
def test_a_lateral_demonstration_changes_lane_where_it_can(rear_ended):
    from adversary.harden.windows import HardenWindowConfig

    record, attack = rear_ended
    made = hardening_windows(record, attack, cached_planner("replay"), "replay", HardenWindowConfig(choice="lateral"))
    info = made.info
    assert info["demonstration"] == "alternative" and abs(info["offset_m"]) > 3.0
    # once the lane change has blended in (2 s), the demonstrated ego is a lane width from the
    # attacked drive's path
    tracks, others = attacked_drive(record, attack, cached_planner("replay"), "replay")
    path = tracks.states[len(others)][tracks.valid[len(others)], :2]
    late = [i for i, k in enumerate(info["steps"]) if k >= info["start_step"] + 20]
    assert late
    window = made.scenes[late[0]]
    here = window.states[0, window.current_index, :2]
    dense = np.concatenate([np.linspace(a, b, 20) for a, b in itertools.pairwise(path)])
    assert np.min(np.linalg.norm(dense - here, axis=1)) == pytest.approx(abs(info["offset_m"]), abs=0.3)


@pytest.mark.slow
def test_no_windows_from_an_attack_without_a_collision(rear_ended):
    record, attack = rear_ended
    made = hardening_windows(record, {**attack, "collision": False}, cached_planner("replay"), "replay")
    assert made.scenes == () and made.info["why"] == "no collision"


@pytest.mark.slow
def test_only_valid_avoidable_failures_become_windows(rear_ended):
    record, attack = rear_ended
    failure = attack["metrics"]["failure"]
    assert failure["valid_attack"] and failure["avoidable"]        # the hand-made brake check counts
    for change, why in (({"valid_attack": False}, "not a valid attack"), ({"avoidable": False}, "unavoidable")):
        doctored = {**attack, "metrics": {**attack["metrics"], "failure": {**failure, **change}}}
        made = hardening_windows(record, doctored, cached_planner("replay"), "replay")
        assert made.scenes == () and why in made.info["why"]


def test_a_space_time_planner_is_fine_tuned_as_one():
    import json
    from pathlib import Path

    from adversary.harden.loop import spacetime_settings

    root = Path(__file__).resolve().parents[3] / "checkpoints"
    st = json.loads((root / "riskmap_st_highway.json").read_text())
    assert spacetime_settings(st) == {"planner": "spacetime", "steps": st["spacetime"]["steps"],
                                      "max_forward": st["spacetime"]["max_forward"],
                                      "max_across": st["spacetime"]["max_across"]}
    assert spacetime_settings(json.loads((root / "riskmap_highway.json").read_text())) == {}


@pytest.mark.slow
def test_round_data_mixes_attack_and_natural_windows_and_keeps_the_original_validation(natural_and_windows,
                                                                                        tmp_path):
    natural, made = natural_and_windows
    write_attack_shard(tmp_path / "windows" / "scene_00009", made.scenes, made.info)
    write_attack_shard(tmp_path / "windows" / "scene_00010", (), {"windows": 0, "why": "no collision"})
    sidecar = {"train": {"val_fraction": 0.15}, "dataset": {}}
    summary = write_round_dataset(tmp_path / "data", natural, sidecar,
                                  [tmp_path / "windows" / "scene_00009", tmp_path / "windows" / "scene_00010"],
                                  natural_share=0.5, seed=0)
    dataset = DemoDataset(tmp_path / "data")
    groups = [dataset.group_of(i) for i in range(len(dataset))]
    assert summary["attack_windows"] == groups.count(ADVERSARIAL_GROUP) == len(made.scenes)
    assert summary["validation_groups"] == ["natural-3"]          # the last of 4 episodes, as trained
    assert summary["natural_windows"] >= summary["attack_windows"] and summary["natural_shards"] >= 1
    assert len(dataset) == (summary["attack_windows"] + summary["natural_windows"]
                            + summary["validation_windows"])
    sample = dataset[0]
    assert sample["future"].shape == (12, 2) and math.isfinite(float(sample["demo"].sum()))
    only_attacks = write_round_dataset(tmp_path / "attacks_only", natural, sidecar,
                                       [tmp_path / "windows" / "scene_00009"], natural_share=0.0, seed=0)
    assert only_attacks["natural_windows"] == 0
    with pytest.raises(InputError, match="no attack gave training windows"):
        write_round_dataset(tmp_path / "none", natural, sidecar, [tmp_path / "windows" / "scene_00010"],
                            natural_share=0.5, seed=0)


@pytest.mark.slow
def test_report_shows_rounds_and_the_same_window_before_and_after(natural_and_windows, tmp_path):
    import shutil

    from adversary.harden.report import write_report

    natural, made = natural_and_windows
    run = tmp_path / "run"
    write_attack_shard(run / "round_1" / "windows" / "scene_00009", made.scenes, made.info)
    write_round_dataset(run / "round_1" / "data", natural, {"train": {"val_fraction": 0.15}, "dataset": {}},
                        [run / "round_1" / "windows" / "scene_00009"], natural_share=0.5, seed=0)
    for suffix in (".safetensors", ".json"):
        shutil.copyfile(f"checkpoints/riskmap_highway{suffix}", run / "round_1" / f"planner{suffix}")
    fresh = {"collisions": 3, "scenes": 10}
    rounds = [{"round": 0, "judged": {"attack": fresh, "closed_loop": {"collisions": 0, "episodes": 4,
                                                                      "distance_m": 400.0}}},
              {"round": 1, "training_attack": {"collisions": 1, "scenes": 2}, "data": {"attack_windows": 9},
               "judged": {"attack": {"collisions": 2, "scenes": 10}, "open_loop": {"ade_m": {"mean": 3.2}}}}]
    (run / "rounds.json").write_text(json.dumps({"rounds": rounds}))
    (run / "harden.json").write_text(json.dumps({"checkpoint": "checkpoints/riskmap_highway"}))
    page = write_report(run).read_text()
    assert "3/10 (30% [11–60])" in page and "2/10 (20%" in page and "3.20" in page
    for r in (0, 1):
        assert (run / "report" / f"before_after_round_{r}.png").stat().st_size > 10_000
        assert f"before_after_round_{r}.png" in page


def test_the_round_planner_samples_and_plans_as_the_original():
    """Only the weights may differ between a round's planner and the one it came from: an original
    from before kinematic timing and gap keeping must not gain them from the fine-tune's sidecar."""
    from riskmap.infra.checkpoint import SIDECAR_FORMAT
    from riskmap.planner.riskmap_planner import sampler_of
    from riskmap.planner.sampler import SamplerConfig

    original = SIDECAR_FORMAT.read({"kind": "riskmap", "planning": {"goal_variance": 2.0}, "irl": {"goal_variance": 5.0},
                                    "sampler": {"samples": 1000, "clusters": 10, "waypoints": 12}})
    trained = {"sampler": {**SamplerConfig().__dict__}, "irl": {"goal_variance": 5.0}, "epoch": 2}
    assert sampler_of(trained) != sampler_of(original)          # the case the rule is for
    side = round_sidecar(trained, original, {"round": 1})
    assert sampler_of(side) == sampler_of(original)
    assert sampler_of(side).timing == "uniform" and not sampler_of(side).keep_gap
    assert side["planning"] == {"goal_variance": 2.0} and side["epoch"] == 2 and side["hardening"] == {"round": 1}


def test_search_shards_are_capped_to_their_share_of_the_attack_windows(tmp_path):
    from adversary.harden.dataset import cap_search_shards

    def shard(name, windows):
        (tmp_path / f"{name}.json").write_text(json.dumps({"windows": windows}))
        return tmp_path / name

    crash = [shard("scene_00001", 6), shard("scene_00002", 4)]
    found = [shard(f"search_cut_in_{k:04d}", 3) for k in range(10)]
    kept, summary = cap_search_shards(crash + found, search_share=0.5, seed=0)
    assert kept[:2] == crash                                  # every CRASH shard stays, first
    assert summary["search_windows_kept"] == 9 == 3 * (len(kept) - 2)   # ≤ 10 CRASH windows, in whole shards
    assert summary["search_windows_found"] == 30 and summary["crash_windows"] == 10
    assert cap_search_shards(crash + found, search_share=0.5, seed=0)[0] == kept      # seeded
    assert cap_search_shards(crash + found, search_share=0.0, seed=0)[0] == crash
    everything, _ = cap_search_shards(crash + found, search_share=0.75, seed=0)
    assert len(everything) == 2 + 10                          # 30 ≤ 3 × 10 windows: nothing dropped


def test_bad_settings_are_one_line_errors(tmp_path, capsys):
    with pytest.raises(InputError, match="natural-share"):
        HardenConfig("c", "s", "n", "o", natural_share=1.0)
    with pytest.raises(InputError, match="search-share"):
        HardenConfig("c", "s", "n", "o", search_share=1.0)
    with pytest.raises(InputError, match="--rounds"):
        HardenConfig("c", "s", "n", "o", rounds=0)
    with pytest.raises(InputError, match="--demonstration 'boldest'"):
        HardenConfig("c", "s", "n", "o", demonstration="boldest")
    code = adversary_main(["harden", "--checkpoint", str(tmp_path / "missing"), "--scenes", str(tmp_path),
                           "--natural", str(tmp_path), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and "missing" in err[0]
    assert not (tmp_path / "run").exists()


def test_report_needs_a_run(tmp_path, capsys):
    assert adversary_main(["harden-report", str(tmp_path)]) != 0
    assert "rounds.json" in capsys.readouterr().err
    (tmp_path / "rounds.json").write_text(json.dumps({"rounds": [{"round": 0, "judged": {}}]}))
    (tmp_path / "harden.json").write_text(json.dumps({"checkpoint": "x"}))
    assert adversary_main(["harden-report", str(tmp_path)]) == 0
    assert "Hardening rounds" in (tmp_path / "report.html").read_text()


def test_a_round_trains_on_the_windows_of_every_earlier_round_too(tmp_path):
    from adversary.harden.loop import earlier_shards

    for name in ("round_1/windows/scene_00002", "round_1/windows/search_cut_in_ab", "round_2/windows/scene_00007"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).with_suffix(".json").write_text("{}")
    (tmp_path / "round_2/windows/scene_00009.npz").write_bytes(b"")       # not committed: no .json
    assert earlier_shards(tmp_path, 1) == []
    assert earlier_shards(tmp_path, 3) == [tmp_path / "round_1/windows/scene_00002",
                                           tmp_path / "round_1/windows/search_cut_in_ab",
                                           tmp_path / "round_2/windows/scene_00007"]


@pytest.mark.parametrize("keep", ["last", "best"])
def test_the_round_planner_is_the_epoch_keep_names(tmp_path, monkeypatch, keep):
    """--keep best makes the fine-tune's best epoch (natural validation ADE) the round's planner,
    --keep last its last one; the sidecar says which."""
    from pathlib import Path

    import adversary.harden.dataset as dataset
    import riskmap.training.train as training
    from adversary.harden.loop import fine_tune

    root = Path(__file__).resolve().parents[3] / "checkpoints"
    original = json.loads((root / "riskmap_highway.json").read_text())

    def fake_train(settings, resume, progress):
        out = Path(settings.out)
        out.mkdir(parents=True)
        for name, epoch in (("last", 1), ("best", 0)):
            (out / f"{name}.safetensors").write_bytes(name.encode())
            (out / f"{name}.json").write_text(json.dumps({**original, "epoch": epoch}))

    monkeypatch.setattr(training, "train", fake_train)
    monkeypatch.setattr(dataset, "write_round_dataset",
                        lambda *args: {"validation_groups": ["g"], "windows": 2})
    config = HardenConfig(str(root / "riskmap_highway"), "s", "n", str(tmp_path), keep=keep)
    fine_tune(config, 1, [], progress=False)
    side = json.loads((tmp_path / "round_1" / "planner.json").read_text())
    assert (tmp_path / "round_1" / "planner.safetensors").read_bytes() == keep.encode()
    assert side["epoch"] == (0 if keep == "best" else 1) and side["hardening"]["kept"] == keep


def test_keep_is_checked_and_older_runs_resume_without_it():
    from adversary.harden.loop import _settings

    with pytest.raises(InputError, match="--keep 'first'"):
        HardenConfig("c", "s", "n", "o", keep="first")
    assert "keep" not in _settings(HardenConfig("c", "s", "n", "o"))
    assert _settings(HardenConfig("c", "s", "n", "o", keep="best"))["keep"] == "best"


def test_the_shipped_hardened_planner_plans_as_its_original_does():
    """checkpoints/riskmap_st_highway_hardened: a space-time round planner with the original's
    sampler and planning settings (only the weights differ), which loads and plans."""
    from pathlib import Path

    from riskmap.registry import make_planner
    from tests.scenes import constant_velocity_scene

    root = Path(__file__).resolve().parents[3] / "checkpoints"
    hardened = json.loads((root / "riskmap_st_highway_hardened.json").read_text())
    original = json.loads((root / "riskmap_st_highway.json").read_text())
    assert hardened["hardening"]["from"].endswith("riskmap_st_highway") and hardened["hardening"]["round"] == 1
    assert hardened["planning"] == original["planning"] and hardened["sampler"] == original["sampler"]
    assert hardened["spacetime"] == original["spacetime"]
    planner = make_planner(f"riskmap:{root / 'riskmap_st_highway_hardened'}", seed=0)
    plan = planner.plan(constant_velocity_scene(n_past=4, n_future=12, ego_speed=20.0))
    assert plan.waypoints.shape == (12, 2) and plan.risk_steps is not None
