import math

import numpy as np
import pytest
import torch

from riskmap.guard.features import EDGE_DIM, NODE_DIM, OBSERVED
from riskmap.guard.metrics import binary_metrics
from riskmap.guard.tgat import TGAT, TGATConfig, TimeEncoding


@pytest.fixture(autouse=True)
def _seeded_init():
    """Model weights come from torch's global generator: seed it so no test depends on what
    ran before it in the session (a random init can leave a ReLU path dead for one event)."""
    torch.manual_seed(0)


def _batch(b=6, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.randn(b, NODE_DIM, generator=g), torch.randn(b, NODE_DIM, generator=g),
            10 * torch.randn(b, OBSERVED, EDGE_DIM, generator=g), torch.ones(b, OBSERVED, dtype=torch.bool))


def test_time_encoding_matches_float64_reference():
    enc = TimeEncoding(4).double()
    dt = torch.tensor([0.0, 0.5, 2.5], dtype=torch.float64)
    omega = enc.omega.detach().numpy()
    ref = np.concatenate([np.cos(np.outer(dt.numpy(), omega)), np.sin(np.outer(dt.numpy(), omega))], 1) / 2.0
    np.testing.assert_allclose(enc(dt).detach().numpy(), ref, atol=1e-12)
    # unit norm: Σ cos² + sin² = m, divided by √m twice
    np.testing.assert_allclose(np.linalg.norm(ref, axis=1), 1.0, atol=1e-12)
    assert enc.omega.requires_grad


def test_logits_shape_and_masked_events_are_ignored():
    model = TGAT(TGATConfig()).eval()
    node_u, node_i, edge, mask = _batch()
    mask[:, :2] = False
    out = model(node_u, node_i, edge, mask)
    assert out.shape == (6,) and torch.isfinite(out).all()
    edge2 = edge.clone()
    edge2[:, :2] = 1e3     # garbage where the events do not exist
    torch.testing.assert_close(model(node_u, node_i, edge2, mask), out)


def test_every_observed_event_reaches_the_score():
    model = TGAT(TGATConfig()).eval()
    node_u, node_i, edge, mask = _batch(b=1)
    base = model(node_u, node_i, edge, mask)
    for j in range(OBSERVED):
        moved = edge.clone()
        moved[0, j, 0] += 5.0
        assert not torch.allclose(model(node_u, node_i, moved, mask), base), j


def test_window_without_events_still_scores():
    model = TGAT(TGATConfig()).eval()
    node_u, node_i, edge, mask = _batch(b=2)
    out = model(node_u, node_i, edge, torch.zeros_like(mask))
    assert torch.isfinite(out).all()


def test_learns_a_separable_toy_problem():
    torch.manual_seed(0)
    n = 64
    node_u, node_i, _, mask = _batch(b=n, seed=1)
    labels = (torch.arange(n) % 2).float()
    # positives: d_s shrinking to overlap; negatives: steady 20 m
    closing = torch.linspace(8.0, -0.5, OBSERVED)
    edge = torch.where(labels[:, None, None] > 0, closing[None, :, None], torch.full((1, OBSERVED, 1), 20.0))
    edge = edge + 0.3 * torch.randn(n, OBSERVED, 1)
    model = TGAT(TGATConfig())
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    for _ in range(40):
        loss = torch.nn.functional.binary_cross_entropy_with_logits(model(node_u, node_i, edge, mask), labels)
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    probs = torch.sigmoid(model(node_u, node_i, edge, mask)).detach().numpy()
    metrics = binary_metrics(labels.numpy(), probs, 0.5)
    assert metrics["auc"] > 0.95 and metrics["accuracy"] > 0.9


def test_binary_metrics_hand_computed():
    labels = np.array([0, 0, 1, 1])
    probs = np.array([0.1, 0.7, 0.4, 0.9])
    m = binary_metrics(labels, probs, 0.5)
    assert m["auc"] == 0.75                       # 3 of 4 (pos, neg) pairs ranked right
    assert math.isclose(m["ap"], (1.0 + 2 / 3) / 2)
    assert m["accuracy"] == 0.5 and m["f1"] == 0.5
    assert binary_metrics(np.zeros(3), np.zeros(3), 0.5)["ap"] is None
