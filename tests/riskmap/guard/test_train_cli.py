import json

import numpy as np
import pytest

from riskmap.guard.dataset import labels_for
from riskmap.guard.features import EDGE_DIM, NODE_DIM, OBSERVED
from riskmap.infra.atomic import write_npz
from tests.riskmap.guard.test_threshold import brute_force_threshold

FRAMES = 40


def _closing_edges(rng, closing):
    """[n, OBSERVED, EDGE_DIM]: d_s closing to overlap where `closing`, else staying apart; the
    neighbour straight ahead (x = d_s + 5 m) approaching at the d_s rate."""
    n = len(closing)
    start = rng.uniform(15, 30, n)
    end = np.where(closing, rng.uniform(-1, 2, n), rng.uniform(10, 30, n))
    ds = np.linspace(start, end, OBSERVED).T
    edge = np.zeros((n, OBSERVED, EDGE_DIM), np.float32)
    edge[..., 0], edge[..., 1] = ds, ds + 5.0
    edge[..., 3] = ((end - start) / 2.5)[:, None]
    return edge


def _fake_split(path, n, seed, frames=True):
    """Windows whose time to contact is short when d_s closes to overlap (learnable, like the
    real data): a third positive, ttc 0.1 .. 2 s; the negatives never touch or only after 3 s.
    With `frames`, FRAMES decision frames of 2 windows each."""
    rng = np.random.default_rng(seed)
    closing = np.arange(n) % 3 == 0
    far = np.where(np.arange(n) % 2 == 0, np.inf, rng.uniform(3.1, 6.0, n))
    ttc = np.where(closing, rng.uniform(0.1, 2.0, n), far).astype(np.float32)
    node = np.tile(np.array([5.0, 2.0, 20.0, 1.0, 0.0, 1.0], np.float32), (n, 1))
    arrays = {"node_u": node, "node_i": node.copy(), "edge": _closing_edges(rng, closing),
              "mask": np.ones((n, OBSERVED), bool), "ttc_s": ttc,
              "neighbour": np.ones(n, np.int32), "last_step": np.arange(n, dtype=np.int32)}
    if frames:
        m = 2 * FRAMES
        frame_node = np.tile(node[:1], (m, 1))
        arrays.update({"frame_node_u": frame_node, "frame_node_i": frame_node.copy(),
                       "frame_edge": _closing_edges(rng, rng.uniform(size=m) < 0.2),
                       "frame_mask": np.ones((m, OBSERVED), bool),
                       "frame": np.repeat(np.arange(FRAMES), 2).astype(np.int32),
                       "frames": np.array([FRAMES], np.int32)})
    write_npz(path, arrays)
    assert node.shape[1] == NODE_DIM
    return ttc


SIZES = [("train", 96), ("val", 30), ("seen", 30), ("unseen", 30)]


def _make_data(root, frames):
    return {split: _fake_split(root / "jobs" / f"{split}_x.npz", n, i, frames)
            for i, (split, n) in enumerate(SIZES)}


@pytest.fixture
def fake_data(tmp_path):
    ttc = _make_data(tmp_path / "data", frames=True)
    return tmp_path / "data", ttc


@pytest.fixture
def frameless_data(tmp_path):
    ttc = _make_data(tmp_path / "frameless", frames=False)
    return tmp_path / "frameless", ttc


def _threshold_on_validation_frames(predictor, data):
    from riskmap.guard.dataset import load_frames
    from riskmap.guard.train import frame_scores

    return frame_scores(predictor.model, load_frames(data, "val"))


def test_train_writes_checkpoint_metrics_curve_and_resumes(fake_data, tmp_path):
    from riskmap.cli import main
    from riskmap.guard.predictor import AccidentPredictor
    from riskmap.guard.threshold import alert_ratio

    data, ttc = fake_data
    run = tmp_path / "run"
    args = ["guard", "train", "--data", str(data), "--out", str(run), "--epochs", "2", "--quiet"]
    assert main(args) == 0
    result = json.loads((run / "result.json").read_text())
    # the default label horizon is 2 s: every closing window (ttc ≤ 2 s) is positive
    assert result["horizon_s"] == 2.0
    assert result["sizes"]["seen"] == {"n": 30, "positives": int(labels_for(ttc["seen"], 2.0).sum())} \
        == {"n": 30, "positives": 10}
    for split in ("seen", "unseen"):
        m = result["test"][split]
        assert m["n"] == 30 and 0.0 <= m["ap"] <= 1.0 and 0.0 <= m["auc"] <= 1.0
        assert m["ttc_mae_s"] is not None and m["ttc_mae_s"] >= 0.0
    assert (run / "curves.png").stat().st_size > 1000
    history = json.loads((run / "history.json").read_text())
    assert [row["epoch"] for row in history] == [0, 1]
    assert main(args) == 2                               # refuses to overwrite
    assert main(args[:-2] + ["4", "--resume", "--quiet"]) == 0
    assert [row["epoch"] for row in json.loads((run / "history.json").read_text())] == [0, 1, 2, 3]

    # The alert threshold: chosen on the validation frames of the best epoch for the default 5 %.
    sidecar = json.loads((run / "best.json").read_text())
    assert sidecar["horizon_s"] == 2.0 and sidecar["model"]["horizon_s"] == 2.0
    assert "validation" in sidecar["alert_threshold_source"]
    predictor = AccidentPredictor.load(run / "best")
    assert predictor.alert_threshold == sidecar["alert_threshold"]
    scores = _threshold_on_validation_frames(predictor, data)
    assert len(scores) == FRAMES
    assert sidecar["alert_threshold"] == brute_force_threshold(scores, 0.05)
    assert sidecar["validation_alert_ratio"] == alert_ratio(scores, sidecar["alert_threshold"]) <= 0.05
    assert sidecar["metrics"]["val"]["at_alert_threshold"]["threshold"] == sidecar["alert_threshold"]
    final = json.loads((run / "result.json").read_text())
    assert final["alert_threshold"] == sidecar["alert_threshold"]
    assert final["validation_alert_ratio"] == sidecar["validation_alert_ratio"]


def test_train_flags_set_the_horizon_the_ttc_weight_and_the_alert_ratio(fake_data, tmp_path, capsys):
    from riskmap.cli import main
    from riskmap.guard.predictor import AccidentPredictor
    from riskmap.guard.threshold import alert_ratio

    assert all(flag in _help(main, capsys) for flag in ("--horizon-s", "--ttc-weight", "--alert-ratio"))
    data, ttc = fake_data
    run = tmp_path / "run"
    assert main(["guard", "train", "--data", str(data), "--out", str(run), "--epochs", "1", "--horizon-s", "1",
                 "--ttc-weight", "0.2", "--alert-ratio", "0.1", "--closest-approach", "--quiet"]) == 0
    assert "label horizon 1 s" in capsys.readouterr().out
    result = json.loads((run / "result.json").read_text())
    for split, n in SIZES:
        expected = int((ttc[split] <= 1.0).sum())
        assert result["sizes"][split] == {"n": n, "positives": expected}
    assert 0 < result["sizes"]["train"]["positives"] < 32             # fewer than at 2 s
    sidecar = json.loads((run / "best.json").read_text())
    assert sidecar["horizon_s"] == 1.0 and sidecar["model"]["horizon_s"] == 1.0
    assert sidecar["model"]["closest_approach"] is True
    assert sidecar["train"]["ttc_weight"] == 0.2 and sidecar["train"]["alert_ratio"] == 0.1
    assert "0.1" in sidecar["alert_threshold_source"]
    predictor = AccidentPredictor.load(run / "best")
    assert predictor.model.config.horizon_s == 1.0 and predictor.model.config.closest_approach
    assert float(predictor.model.query_times[-1]) == pytest.approx(4.0)
    scores = _threshold_on_validation_frames(predictor, data)
    assert sidecar["alert_threshold"] == brute_force_threshold(scores, 0.1)
    assert 0.0 <= sidecar["alert_threshold"] <= 1.0
    assert sidecar["validation_alert_ratio"] == alert_ratio(scores, sidecar["alert_threshold"]) <= 0.1


def _help(main, capsys) -> str:
    with pytest.raises(SystemExit):
        main(["guard", "train", "--help"])
    return capsys.readouterr().out


def test_without_decision_frames_the_threshold_is_the_fixed_one(frameless_data, tmp_path):
    from riskmap.guard.config import GuardTrainConfig
    from riskmap.guard.predictor import AccidentPredictor
    from riskmap.guard.train import train

    data, _ = frameless_data
    result = train(data, tmp_path / "run", GuardTrainConfig(epochs=1), progress=False)
    sidecar = json.loads((tmp_path / "run" / "best.json").read_text())
    assert sidecar["alert_threshold"] == result["alert_threshold"] == 0.6
    assert "fixed" in sidecar["alert_threshold_source"]
    assert sidecar["validation_alert_ratio"] is None
    assert AccidentPredictor.load(tmp_path / "run" / "best").alert_threshold == 0.6


@pytest.mark.parametrize("changes, flag", [({"ttc_weight": -0.1}, "--ttc-weight"),
                                           ({"ttc_weight": float("nan")}, "--ttc-weight"),
                                           ({"alert_ratio": 0.0}, "--alert-ratio"),
                                           ({"alert_ratio": 1.0}, "--alert-ratio"),
                                           ({"horizon_s": 0.0}, "--horizon-s"),
                                           ({"horizon_s": 3.5}, "--horizon-s")])
def test_train_config_refuses_bad_settings(changes, flag):
    from rasterize.errors import InputError
    from riskmap.guard.config import GuardTrainConfig, TGATConfig

    model = TGATConfig(**{k: v for k, v in changes.items() if k == "horizon_s"})
    with pytest.raises(InputError, match=flag):
        GuardTrainConfig(model=model, **{k: v for k, v in changes.items() if k != "horizon_s"})


def test_missing_split_is_a_one_line_error(tmp_path, capsys):
    from riskmap.cli import main

    assert main(["guard", "train", "--data", str(tmp_path), "--out", str(tmp_path / "r"), "--quiet"]) == 2
    assert "riskmap guard collect" in capsys.readouterr().err


def test_evaluate_scores_any_split_like_the_training_run(fake_data, tmp_path):
    from sklearn.metrics import average_precision_score

    from riskmap.cli import main
    from riskmap.guard.dataset import load_split
    from riskmap.guard.evaluate import evaluate_checkpoint
    from riskmap.guard.predictor import AccidentPredictor
    from riskmap.guard.train import _tensors, predict

    data, _ = fake_data
    run = tmp_path / "run"
    assert main(["guard", "train", "--data", str(data), "--out", str(run), "--epochs", "2", "--horizon-s", "1",
                 "--quiet"]) == 0
    ttc = _fake_split(data / "jobs" / "advhighway_x.npz", 45, 9)       # a split the training never saw
    result = evaluate_checkpoint(run / "best", data, ["seen", "advhighway"])
    sidecar = json.loads((run / "best.json").read_text())
    assert result["seen"]["ap"] == pytest.approx(sidecar["metrics"]["seen"]["ap"])
    # labelled at the checkpoint's horizon (1 s), scored at its alert threshold
    split = load_split(data, "advhighway", 1.0)
    predictor = AccidentPredictor.load(run / "best")
    probs, predicted_ttc = predict(predictor.model, _tensors(split))
    assert result["advhighway"]["n"] == 45
    assert result["advhighway"]["positives"] == int((ttc <= 1.0).sum()) < 15
    assert result["advhighway"]["ap"] == pytest.approx(average_precision_score(split["label"], probs))
    assert result["advhighway"]["at_alert_threshold"]["threshold"] == sidecar["alert_threshold"]
    positive = split["label"] == 1
    assert result["advhighway"]["ttc_mae_s"] == pytest.approx(
        np.mean(np.abs(predicted_ttc[positive] - split["ttc_s"][positive].astype(np.float64))), rel=1e-6)
    out = tmp_path / "eval.json"
    assert main(["guard", "evaluate", "--checkpoint", str(run / "best"), "--data", str(data),
                 "--splits", "unseen,advhighway", "--out", str(out)]) == 0
    assert set(json.loads(out.read_text())["splits"]) == {"unseen", "advhighway"}
    assert main(["guard", "evaluate", "--checkpoint", str(run / "best"), "--data", str(data),
                 "--splits", "nosuch"]) == 2
