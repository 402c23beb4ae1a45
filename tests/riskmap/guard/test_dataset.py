import numpy as np
import pytest

from rasterize.errors import InputError
from rasterize.tracks import Tracks
from riskmap.guard.dataset import (
    GuardCollectConfig,
    extract_windows,
    labels_for,
    load_frames,
    load_job,
    load_split,
    plan_jobs,
)
from riskmap.guard.features import (
    EDGE_DIM,
    MAX_HORIZON_S,
    NODE_DIM,
    OBSERVED,
    relative_motion,
    window_features,
)
from riskmap.infra.atomic import write_npz

CAR = [5.0, 2.0]
HZ = 10


def _recording(crash_step=25, far=False):
    """10 Hz: the ego drives east at 10 m/s from x = 0 into a car stopped at x = crash_step + 5
    (touching at `crash_step`, where d_s = 0); a third car passes 10 m to the side at the ego's
    speed, 5 m ahead; with `far`, a fourth car keeps 60 m to the other side (never among the 2
    nearest)."""
    n_steps = crash_step + 1
    t = 0.1 * np.arange(n_steps)
    n_agents = 4 if far else 3
    states = np.zeros((n_agents, n_steps, 6))
    states[..., 2] = 1.0
    states[0, :, 0], states[0, :, 4] = 10.0 * t, 10.0
    states[1, :, 0] = crash_step + 5.0
    states[2, :, 0], states[2, :, 1], states[2, :, 4] = 5.0 + 10.0 * t, 10.0, 10.0
    if far:
        states[3, :, 0], states[3, :, 1], states[3, :, 4] = 10.0 * t, -60.0, 10.0
    valid = np.ones((n_agents, n_steps), bool)
    return Tracks(states, valid, np.array([CAR] * n_agents), np.zeros(n_agents, np.int8))


def _extract(crashed=True, negatives=100, **kw):
    config = GuardCollectConfig(control_hz=HZ, negatives_per_episode=negatives)
    return extract_windows(_recording(**kw), 0, crashed, config, np.random.default_rng(0))


def _positive(w):
    return labels_for(w["ttc_s"], MAX_HORIZON_S) == 1


def test_crash_gives_positive_windows_for_the_partner_only():
    w = _extract(crash_step=25)
    pos = _positive(w)
    # last observed event 0.1 s .. 2.5 s before the crash step (25): every step 0..24 (3 s reach
    # further back than the recording)
    assert sorted(w["last_step"][pos]) == list(range(0, 25))
    assert (w["neighbour"][pos] == 1).all()
    assert "label" not in w
    # negatives every 0.5 s up to the step before the crash, excluding the positive pairs
    neg = sorted(zip(w["neighbour"][~pos].tolist(), w["last_step"][~pos].tolist()))
    assert neg == [(2, 5), (2, 10), (2, 15), (2, 20)]


def test_time_to_contact_of_the_partner_windows_is_exact_and_labels_follow_the_horizon():
    crash = 45
    w = _extract(crash_step=crash)
    partner = w["neighbour"] == 1
    steps = w["last_step"][partner]
    reference = (crash - steps.astype(np.float64)) / HZ          # float64 reference
    # the stored float32 is the float64 time rounded once
    np.testing.assert_array_equal(w["ttc_s"][partner], reference.astype(np.float32))
    assert w["ttc_s"].dtype == np.float32
    # positives: the partner's windows ending at every control step of the 3 s before the crash
    within = w["ttc_s"] <= MAX_HORIZON_S + 1e-4
    assert sorted(w["last_step"][within]) == list(range(crash - 30, crash))
    assert (w["neighbour"][within] == 1).all()
    # 10, 20, 30 positives at 1, 2, 3 s: steps 35..44, 25..44, 15..44
    for horizon, count, first in ((1.0, 10, 35), (2.0, 20, 25), (3.0, 30, 15)):
        labels = labels_for(w["ttc_s"], horizon)
        assert labels.dtype == np.int8 and labels.sum() == count, horizon
        assert sorted(w["last_step"][labels == 1]) == list(range(first, crash)), horizon
        np.testing.assert_array_equal(labels, (reference_ttc(w, crash) <= horizon).astype(np.int8))
    # the partner earlier than 3 s: negatives with a known, longer time to contact
    early = partner & ~within
    assert sorted(w["last_step"][early]) == [5, 10]
    np.testing.assert_array_equal(w["ttc_s"][early], np.float32([4.0, 3.5])[np.argsort(w["last_step"][early])])
    # every other window never touches the ego
    assert np.isinf(w["ttc_s"][~partner]).all()
    assert ((w["ttc_s"] > MAX_HORIZON_S) | within).all()


def reference_ttc(w, crash):
    """ttc per window from (neighbour, last_step) alone, float64."""
    return np.where(w["neighbour"] == 1, (crash - w["last_step"].astype(np.float64)) / HZ, np.inf)


def test_window_edges_are_d_s_and_relative_motion_at_half_second_segments():
    node_u, node_i, edge, mask = window_features(_recording(), 0, 1, 24, 5)
    assert edge.shape == (OBSERVED, EDGE_DIM) and EDGE_DIM == 5
    # events at steps -1 (absent), 4, 9, 14, 19, 24: ego at x = step m, d_s = 30 − x − 5
    assert mask.tolist() == [False] + [True] * (OBSERVED - 1)
    np.testing.assert_allclose(edge[1:, 0], [21.0, 16.0, 11.0, 6.0, 1.0], atol=1e-5)
    # the stopped car ahead: 30 − x m straight ahead, closing at 10 m/s, no lateral part
    np.testing.assert_allclose(edge[1:, 1], [26.0, 21.0, 16.0, 11.0, 6.0], atol=1e-5)
    np.testing.assert_allclose(edge[1:, 2:], np.tile([0.0, -10.0, 0.0], (5, 1)), atol=1e-5)
    assert (edge[0] == 0.0).all()
    np.testing.assert_allclose(node_u, [5.0, 2.0, 10.0, 1.0, 0.0, 1.0])
    np.testing.assert_allclose(node_i, [5.0, 2.0, 0.0, 1.0, 0.0, 1.0])


def test_relative_motion_in_a_rotated_ego_frame_matches_a_hand_computed_reference():
    # ego at (1, 2) heading north (90°) at 5 m/s; neighbour at (4, 6) heading east at 3 m/s
    su = np.array([1.0, 2.0, 0.0, 1.0, 5.0, 0.0])
    si = np.array([4.0, 6.0, 1.0, 0.0, 3.0, 0.0])
    # world offset (3, 4): 4 m ahead, 3 m to the right (left = −3); world relative velocity
    # (3, 0) − (0, 5) = (3, −5): closing 5 m/s from ahead, 3 m/s to the right
    np.testing.assert_allclose(relative_motion(su, si), [4.0, -3.0, -5.0, -3.0], atol=1e-12)


def test_relative_motion_broadcasts_against_a_float64_rotation_reference():
    rng = np.random.default_rng(3)
    n = 40
    yaw_u, yaw_i = rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)
    su = np.column_stack([rng.normal(0, 20, (n, 2)), np.cos(yaw_u), np.sin(yaw_u), rng.uniform(0, 30, n),
                          np.zeros(n)])
    si = np.column_stack([rng.normal(0, 20, (n, 2)), np.cos(yaw_i), np.sin(yaw_i), rng.uniform(0, 30, n),
                          np.zeros(n)])
    ref = np.zeros((n, 4))
    for k in range(n):
        rot = np.array([[np.cos(yaw_u[k]), np.sin(yaw_u[k])], [-np.sin(yaw_u[k]), np.cos(yaw_u[k])]])  # R(−yaw)
        ref[k, :2] = rot @ (si[k, :2] - su[k, :2])
        v_u = su[k, 4] * np.array([np.cos(yaw_u[k]), np.sin(yaw_u[k])])
        v_i = si[k, 4] * np.array([np.cos(yaw_i[k]), np.sin(yaw_i[k])])
        ref[k, 2:] = rot @ (v_i - v_u)
    out = relative_motion(su, si)
    assert out.shape == (n, 4)
    np.testing.assert_allclose(out, ref, atol=1e-9)
    # [A, S, 6] arrays broadcast as well
    np.testing.assert_allclose(relative_motion(su.reshape(4, 10, 6), si.reshape(4, 10, 6)),
                               ref.reshape(4, 10, 4), atol=1e-9)


def test_no_crash_no_positive_and_no_window_without_a_known_future():
    # 46 steps, not crashed: the last window ends 3 s (30 steps) before the last step 45
    w = _extract(crashed=False, crash_step=45)
    assert np.isinf(w["ttc_s"]).all()
    assert labels_for(w["ttc_s"], MAX_HORIZON_S).sum() == 0
    assert w["last_step"].max() <= 45 - 30
    assert sorted(set(w["last_step"].tolist())) == [5, 10, 15]


def test_negatives_are_capped_half_nearest():
    rng = np.random.default_rng(0)
    tracks = _recording(crash_step=45)
    every = extract_windows(tracks, 0, True,
                            GuardCollectConfig(control_hz=HZ, negatives_per_episode=100), rng)
    w = extract_windows(tracks, 0, True, GuardCollectConfig(control_hz=HZ, negatives_per_episode=2), rng)
    assert (~_positive(w)).sum() == 2 and _positive(w).sum() == 30
    # one of the two kept is the nearest candidate by d_s at its last event
    neg = ~_positive(every)
    nearest = np.argmin(every["edge"][neg, -1, 0])
    pair = (int(every["neighbour"][neg][nearest]), int(every["last_step"][neg][nearest]))
    assert pair in set(zip(w["neighbour"].tolist(), w["last_step"].tolist()))


def _reference_ds(states, sizes, ego, agent, step):
    """d_s of two boxes, float64, written out: d − s_ego − s_agent along the line of centres."""
    delta = states[agent, step, :2] - states[ego, step, :2]
    d = np.hypot(*delta)
    direction = np.arctan2(delta[1], delta[0])

    def s(a):
        phi = direction - np.arctan2(states[a, step, 3], states[a, step, 2])
        return 0.5 * sizes[a, 0] * abs(np.cos(phi)) + 0.5 * sizes[a, 1] * abs(np.sin(phi))

    return d - s(ego) - s(agent)


def test_decision_frames_score_the_two_nearest_every_half_second():
    crash = 45
    tracks = _recording(crash_step=crash, far=True)
    config = GuardCollectConfig(control_hz=HZ, negatives_per_episode=100)
    w = extract_windows(tracks, 0, True, config, np.random.default_rng(0))
    n_steps = crash + 1
    frame_steps = list(range(5, n_steps, 5))
    assert w["frames"].tolist() == [len(frame_steps)] == [9]
    np.testing.assert_array_equal(w["frame"], np.repeat(np.arange(9), 2))
    assert w["frame_node_u"].shape == (18, NODE_DIM) and w["frame_edge"].shape == (18, OBSERVED, EDGE_DIM)
    for f, k in enumerate(frame_steps):
        ds = {a: _reference_ds(tracks.states, tracks.sizes, 0, a, k) for a in (1, 2, 3)}
        expected = sorted(ds, key=ds.get)[:2]
        assert 3 not in expected
        for slot, agent in enumerate(expected):
            row = 2 * f + slot
            ref = window_features(tracks, 0, agent, k, 5)
            np.testing.assert_array_equal(w["frame_node_i"][row], ref[1])
            np.testing.assert_array_equal(w["frame_edge"][row], ref[2])
            np.testing.assert_array_equal(w["frame_mask"][row], ref[3])
            np.testing.assert_allclose(w["frame_edge"][row, -1, 0], ds[agent], atol=1e-4)
    # the car ahead becomes the nearer one once it is closer than the passing car (≈ 7.2 m)
    assert w["frame_edge"][0, -1, 1] == pytest.approx(5.0, abs=1e-4)       # the passing car first
    assert w["frame_edge"][-2, -1, 0] == pytest.approx(0.0, abs=1e-4)      # the crash partner at the end


def test_frames_of_a_non_crashed_episode_cover_the_whole_recording():
    w = _extract(crashed=False, crash_step=33)
    assert w["frames"].tolist() == [len(range(5, 34, 5))]
    assert w["frame"].max() == len(range(5, 34, 5)) - 1


@pytest.mark.parametrize("horizon", [0.0, -1.0, 4.0, 3.01, float("nan")])
def test_labels_for_rejects_horizons_the_data_does_not_cover(horizon):
    with pytest.raises(InputError, match="horizon"):
        labels_for(np.array([0.5, np.inf], np.float32), horizon)


def test_labels_for_absorbs_float32_rounding_only():
    ttc = np.array([0.1, 1.0, 2.0, 2.1, 3.0, 3.5, np.inf], np.float32)
    assert labels_for(ttc, 2.0).tolist() == [1, 1, 1, 0, 0, 0, 0]
    assert labels_for(ttc, 3.0).tolist() == [1, 1, 1, 1, 1, 0, 0]
    assert labels_for(np.float32([0.3]), 0.3).tolist() == [1]        # float32(0.3) > 0.3


def _write_job(path, w, **changes):
    arrays = {k: v for k, v in w.items()}
    arrays.update(changes)
    write_npz(path, {k: v for k, v in arrays.items() if v is not None})


def test_load_job_refuses_old_format_and_other_edge_dimensions(tmp_path):
    w = _extract(crash_step=45)
    good = tmp_path / "good.npz"
    _write_job(good, w)
    assert set(load_job(good)) >= {"node_u", "ttc_s", "frame_edge", "frames"}
    old = tmp_path / "old.npz"
    _write_job(old, w, ttc_s=None, label=labels_for(w["ttc_s"], 1.0), edge=w["edge"][..., :1])
    with pytest.raises(InputError, match="older version") as err:
        load_job(old)
    assert str(old) in str(err.value)
    narrow = tmp_path / "narrow.npz"
    _write_job(narrow, w, edge=w["edge"][..., :1])
    with pytest.raises(InputError, match="1 edge features") as err:
        load_job(narrow)
    assert str(narrow) in str(err.value)
    bad_frame = tmp_path / "bad_frame.npz"
    poisoned = w["frame_edge"].copy()
    poisoned[0, 0, 0] = np.nan
    _write_job(bad_frame, w, frame_edge=poisoned)
    with pytest.raises(InputError, match="frame_edge"):
        load_job(bad_frame)


def test_load_split_labels_for_the_horizon_and_load_frames_offsets_the_jobs(tmp_path):
    crashed = _extract(crash_step=45)
    calm = _extract(crashed=False, crash_step=33)
    _write_job(tmp_path / "jobs" / "val_a.npz", crashed)
    _write_job(tmp_path / "jobs" / "val_b.npz", calm)
    for horizon, positives in ((1.0, 10), (2.0, 20), (3.0, 30)):
        split = load_split(tmp_path, "val", horizon)
        assert split["label"].sum() == positives
        assert len(split["label"]) == len(crashed["ttc_s"]) + len(calm["ttc_s"])
        np.testing.assert_array_equal(split["job"], np.repeat([0, 1], [len(crashed["ttc_s"]), len(calm["ttc_s"])]))
    with pytest.raises(InputError):
        load_split(tmp_path, "val", 4.0)
    frames = load_frames(tmp_path, "val")
    n_a, n_b = int(crashed["frames"][0]), int(calm["frames"][0])
    assert frames["frames"] == n_a + n_b
    np.testing.assert_array_equal(frames["frame"], np.concatenate([crashed["frame"], calm["frame"] + n_a]))
    np.testing.assert_array_equal(frames["edge"], np.concatenate([crashed["frame_edge"], calm["frame_edge"]]))
    assert set(frames) == {"node_u", "node_i", "edge", "mask", "frame", "frames"}
    # a split one of whose files holds no frames has none
    _write_job(tmp_path / "jobs" / "val_c.npz", calm, frame_node_u=None, frame_node_i=None, frame_edge=None,
               frame_mask=None, frame=None, frames=None)
    assert load_frames(tmp_path, "val") is None


def test_splits_are_disjoint_and_paired():
    config = GuardCollectConfig(seen_envs=("highway-v0",), unseen_envs=("intersection-v0",),
                                train_episodes=10, seen_test_episodes=3, unseen_episodes=2, planner_every=4)
    jobs = plan_jobs(config)
    keys = {(j.env_id, j.driver, j.seed, j.episode, j.aggressive) for j in jobs}
    assert len(keys) == len(jobs)
    by_split = {s: {(j.env_id, j.seed, j.episode) for j in jobs if j.split == s}
                for s in ("train", "val", "seen", "unseen")}
    assert not by_split["train"] & by_split["val"]
    assert {j.seed for j in jobs if j.split == "seen"} == {config.seed + 1}
    assert {j.env_id for j in jobs if j.split == "unseen"} == {"intersection-v0"}
    # every natural run has its aggressive twin on the same seed and episode
    nat = {(j.env_id, j.driver, j.seed, j.episode) for j in jobs if not j.aggressive}
    agg = {(j.env_id, j.driver, j.seed, j.episode) for j in jobs if j.aggressive}
    assert nat == agg
    assert any(j.driver.startswith("riskmap:") for j in jobs)


@pytest.mark.slow
def test_collect_cli_writes_resumable_jobs(tmp_path):
    from riskmap.cli import main

    args = ["guard", "collect", "--out", str(tmp_path / "g"), "--seen-envs", "highway-v0",
            "--unseen-envs", "intersection-v0", "--train-episodes", "2", "--seen-episodes", "1",
            "--unseen-episodes", "1", "--planner-every", "99", "--episode-s", "2", "--quiet"]
    assert main(args) == 0
    jobs = sorted(p.name for p in (tmp_path / "g" / "jobs").glob("*.npz"))
    assert len(jobs) > 0
    for name in jobs:                            # the new format: times to contact and decision frames
        arrays = load_job(tmp_path / "g" / "jobs" / name)
        assert "ttc_s" in arrays and "label" not in arrays and arrays["edge"].shape[-1] == EDGE_DIM
        # 2 s at 10 Hz: a decision frame every 0.5 s, each scoring the 2 nearest of the neighbours
        assert 1 <= arrays["frames"][0] <= len(range(5, 21, 5))
        assert arrays["frame"].max() == arrays["frames"][0] - 1
        assert np.bincount(arrays["frame"]).max() <= 2
    assert main(args) == 2                       # refuses to overwrite
    assert main(args + ["--resume"]) == 0
    assert sorted(p.name for p in (tmp_path / "g" / "jobs").glob("*.npz")) == jobs
