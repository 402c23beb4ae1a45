import json

import numpy as np
import pytest

from riskmap.atomic import write_npz
from riskmap.guard.features import EDGE_DIM, NODE_DIM, OBSERVED


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
