import json

import numpy as np
import pytest

from riskmap.guard.features import EDGE_DIM, NODE_DIM, OBSERVED
from riskmap.infra.atomic import write_npz


def _fake_split(path, n, seed):
    """Windows whose label is whether d_s closes to overlap: learnable, like the real data."""
    rng = np.random.default_rng(seed)
    label = (np.arange(n) % 3 == 0).astype(np.int8)
    start = rng.uniform(15, 30, n)
    end = np.where(label == 1, rng.uniform(-1, 2, n), rng.uniform(10, 30, n))
    edge = np.linspace(start, end, OBSERVED).T[..., None].astype(np.float32)
    node = np.tile(np.array([5.0, 2.0, 20.0, 1.0, 0.0, 1.0], np.float32), (n, 1))
    write_npz(path, {"node_u": node, "node_i": node.copy(), "edge": edge.reshape(n, OBSERVED, EDGE_DIM),
                     "mask": np.ones((n, OBSERVED), bool), "label": label,
                     "neighbour": np.ones(n, np.int32), "last_step": np.arange(n, dtype=np.int32)})
    assert node.shape[1] == NODE_DIM


@pytest.fixture
def fake_data(tmp_path):
    for i, (split, n) in enumerate([("train", 96), ("val", 30), ("seen", 30), ("unseen", 30)]):
        _fake_split(tmp_path / "data" / "jobs" / f"{split}_x.npz", n, i)
    return tmp_path / "data"


def test_train_writes_checkpoint_metrics_curve_and_resumes(fake_data, tmp_path):
    from riskmap.cli import main
    from riskmap.guard.predictor import AccidentPredictor

    run = tmp_path / "run"
    args = ["guard", "train", "--data", str(fake_data), "--out", str(run), "--epochs", "2", "--quiet"]
    assert main(args) == 0
    result = json.loads((run / "result.json").read_text())
    assert result["sizes"]["seen"] == {"n": 30, "positives": 10}
    for split in ("seen", "unseen"):
        m = result["test"][split]
        assert m["n"] == 30 and 0.0 <= m["ap"] <= 1.0 and 0.0 <= m["auc"] <= 1.0
    assert (run / "curves.png").stat().st_size > 1000
    history = json.loads((run / "history.json").read_text())
    assert [row["epoch"] for row in history] == [0, 1]
    assert main(args) == 2                               # refuses to overwrite
    assert main(args[:-2] + ["4", "--resume", "--quiet"]) == 0
    assert [row["epoch"] for row in json.loads((run / "history.json").read_text())] == [0, 1, 2, 3]
    predictor = AccidentPredictor.load(run / "best")
    assert predictor.alert_threshold == 0.6


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

    run = tmp_path / "run"
    assert main(["guard", "train", "--data", str(fake_data), "--out", str(run), "--epochs", "2", "--quiet"]) == 0
    _fake_split(fake_data / "jobs" / "advhighway_x.npz", 45, 9)       # a split the training never saw
    result = evaluate_checkpoint(run / "best", fake_data, ["seen", "advhighway"])
    sidecar = json.loads((run / "best.json").read_text())
    assert result["seen"]["ap"] == pytest.approx(sidecar["metrics"]["seen"]["ap"])
    split = load_split(fake_data, "advhighway")
    probs = predict(AccidentPredictor.load(run / "best").model, _tensors(split))
    assert result["advhighway"]["n"] == 45 and result["advhighway"]["positives"] == 15
    assert result["advhighway"]["ap"] == pytest.approx(average_precision_score(split["label"], probs))
    assert result["advhighway"]["at_alert_threshold"]["threshold"] == 0.6
    out = tmp_path / "eval.json"
    assert main(["guard", "evaluate", "--checkpoint", str(run / "best"), "--data", str(fake_data),
                 "--splits", "unseen,advhighway", "--out", str(out)]) == 0
    assert set(json.loads(out.read_text())["splits"]) == {"unseen", "advhighway"}
    assert main(["guard", "evaluate", "--checkpoint", str(run / "best"), "--data", str(fake_data),
                 "--splits", "nosuch"]) == 2
