import numpy as np
import pytest

from riskmap.guard.dataset import GuardCollectConfig, extract_windows, plan_jobs
from riskmap.guard.features import OBSERVED, window_features

CAR = [5.0, 2.0]


def _recording():
    """10 Hz: the ego drives east at 10 m/s from x = 0 into a car stopped at x = 30 (crash at
    step 25, where d_s = 30 − 25 − 5 = 0); a third car passes 10 m to the side."""
    n_steps = 26
    t = 0.1 * np.arange(n_steps)
    states = np.zeros((3, n_steps, 6))
    states[..., 2] = 1.0
    states[0, :, 0], states[0, :, 4] = 10.0 * t, 10.0
    states[1, :, 0] = 30.0
    states[2, :, 0], states[2, :, 1], states[2, :, 4] = 5.0 + 10.0 * t, 10.0, 10.0
    valid = np.ones((3, n_steps), bool)
    return states, valid, np.array([CAR] * 3), np.zeros(3, np.int8)


def test_crash_gives_positive_windows_for_the_partner_only():
    states, valid, sizes, kinds = _recording()
    config = GuardCollectConfig(control_hz=10, negatives_per_episode=100)
    w = extract_windows(states, valid, sizes, kinds, 0, True, config, np.random.default_rng(0))
    pos = w["label"] == 1
    # last observed event 0.1 s .. 1.0 s before the crash step (25): steps 15..24
    assert sorted(w["last_step"][pos]) == list(range(15, 25))
    assert (w["neighbour"][pos] == 1).all()
    # negatives every 0.5 s up to the step before the crash, excluding the positive pairs
    neg = sorted(zip(w["neighbour"][~pos].tolist(), w["last_step"][~pos].tolist()))
    assert neg == [(1, 5), (1, 10), (2, 5), (2, 10), (2, 15), (2, 20)]


def test_window_edges_are_d_s_at_half_second_segments():
    states, valid, sizes, kinds = _recording()
    node_u, node_i, edge, mask = window_features(states, valid, sizes, kinds, 0, 1, 24, 5)
    # events at steps -1 (absent), 4, 9, 14, 19, 24: ego at x = step m, d_s = 30 − x − 5
    assert mask.tolist() == [False] + [True] * (OBSERVED - 1)
    np.testing.assert_allclose(edge[1:, 0], [21.0, 16.0, 11.0, 6.0, 1.0], atol=1e-5)
    assert edge[0, 0] == 0.0
    np.testing.assert_allclose(node_u, [5.0, 2.0, 10.0, 1.0, 0.0, 1.0])
    np.testing.assert_allclose(node_i, [5.0, 2.0, 0.0, 1.0, 0.0, 1.0])


def test_no_crash_no_positive_and_no_window_without_a_known_future():
    states, valid, sizes, kinds = _recording()
    config = GuardCollectConfig(control_hz=10, negatives_per_episode=100)
    w = extract_windows(states, valid, sizes, kinds, 0, False, config, np.random.default_rng(0))
    assert w["label"].sum() == 0
    assert w["last_step"].max() <= 25 - 10      # the 1 s after the last event is recorded


def test_negatives_are_capped_half_nearest():
    states, valid, sizes, kinds = _recording()
    rng = np.random.default_rng(0)
    every = extract_windows(states, valid, sizes, kinds, 0, True,
                            GuardCollectConfig(control_hz=10, negatives_per_episode=100), rng)
    w = extract_windows(states, valid, sizes, kinds, 0, True,
                        GuardCollectConfig(control_hz=10, negatives_per_episode=2), rng)
    assert (w["label"] == 0).sum() == 2 and (w["label"] == 1).sum() == 10
    # one of the two kept is the nearest candidate by d_s at its last event
    neg = every["label"] == 0
    nearest = np.argmin(every["edge"][neg, -1, 0])
    pair = (int(every["neighbour"][neg][nearest]), int(every["last_step"][neg][nearest]))
    assert pair in set(zip(w["neighbour"].tolist(), w["last_step"].tolist()))


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
    assert main(args) == 2                       # refuses to overwrite
    assert main(args + ["--resume"]) == 0
    assert sorted(p.name for p in (tmp_path / "g" / "jobs").glob("*.npz")) == jobs
