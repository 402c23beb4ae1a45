import math

import numpy as np
import pytest
import torch

from riskmap.guard.features import EDGE_DIM, EVENT_TIMES_S, HORIZONS_S, NODE_DIM, OBSERVED, target_time_s
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


def test_forward_returns_logits_and_a_non_negative_time_to_contact():
    model = TGAT(TGATConfig()).eval()
    out = model(*_batch())
    assert isinstance(out, tuple) and len(out) == 2
    logits, ttc = out
    assert logits.shape == (6,) and ttc.shape == (6,)
    assert torch.isfinite(logits).all() and torch.isfinite(ttc).all() and (ttc >= 0).all()
    # the time to contact is the softplus of the score MLP's second output
    node_u, node_i, edge, mask = _batch()
    captured = {}
    model.score.register_forward_hook(lambda module, args, result: captured.setdefault("raw", result))
    _, ttc = model(node_u, node_i, edge, mask)
    ref = np.log1p(np.exp(captured["raw"][:, 1].detach().double().numpy()))
    np.testing.assert_allclose(ttc.detach().double().numpy(), ref, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(model(node_u, node_i, edge, mask)[0].detach().numpy(),
                               captured["raw"][:, 0].detach().numpy(), atol=1e-6)


def test_logits_shape_and_masked_events_are_ignored():
    model = TGAT(TGATConfig()).eval()
    node_u, node_i, edge, mask = _batch()
    mask[:, :2] = False
    logits, ttc = model(node_u, node_i, edge, mask)
    assert logits.shape == (6,) and torch.isfinite(logits).all()
    edge2 = edge.clone()
    edge2[:, :2] = 1e3     # garbage where the events do not exist
    logits2, ttc2 = model(node_u, node_i, edge2, mask)
    torch.testing.assert_close(logits2, logits)
    torch.testing.assert_close(ttc2, ttc)


@pytest.mark.parametrize("feature", range(EDGE_DIM))
def test_every_observed_event_and_edge_feature_reaches_the_score(feature):
    model = TGAT(TGATConfig()).eval()
    node_u, node_i, edge, mask = _batch(b=1)
    base, base_ttc = model(node_u, node_i, edge, mask)
    for j in range(OBSERVED):
        moved = edge.clone()
        moved[0, j, feature] += 5.0
        logits, ttc = model(node_u, node_i, moved, mask)
        assert not torch.allclose(logits, base), (j, feature)
        assert not torch.allclose(ttc, base_ttc), (j, feature)


def test_edge_features_are_scaled_per_kind():
    config = TGATConfig(ds_scale_m=10.0, position_scale_m=20.0, speed_scale_mps=4.0)
    model = TGAT(config)
    np.testing.assert_array_equal(model.edge_scale.numpy(), [10.0, 20.0, 20.0, 4.0, 4.0])


@pytest.mark.parametrize("horizon", HORIZONS_S)
def test_query_time_is_the_target_event_horizon_after_the_last(horizon):
    model = TGAT(TGATConfig(horizon_s=horizon))
    assert target_time_s(horizon) == EVENT_TIMES_S[-1] + horizon == 3.0 + horizon
    np.testing.assert_allclose(model.query_times.numpy(), list(EVENT_TIMES_S) + [3.0 + horizon])


def test_the_horizon_changes_the_prediction_with_the_same_weights():
    torch.manual_seed(0)
    short = TGAT(TGATConfig(horizon_s=1.0)).eval()
    long = TGAT(TGATConfig(horizon_s=3.0)).eval()
    long.load_state_dict(short.state_dict())              # the query times are not weights
    batch = _batch(b=4)
    (l1, t1), (l3, t3) = short(*batch), long(*batch)
    assert not torch.allclose(l1, l3) and not torch.allclose(t1, t3)
    same = TGAT(TGATConfig(horizon_s=1.0)).eval()
    same.load_state_dict(short.state_dict())
    torch.testing.assert_close(same(*batch)[0], l1)


def test_window_without_events_still_scores():
    model = TGAT(TGATConfig()).eval()
    node_u, node_i, edge, mask = _batch(b=2)
    logits, ttc = model(node_u, node_i, edge, torch.zeros_like(mask))
    assert torch.isfinite(logits).all() and torch.isfinite(ttc).all() and (ttc >= 0).all()


def test_learns_a_separable_toy_problem():
    torch.manual_seed(0)
    n = 64
    node_u, node_i, _, mask = _batch(b=n, seed=1)
    labels = (torch.arange(n) % 2).float()
    # positives: d_s shrinking to overlap; negatives: steady 20 m (the other features zero)
    closing = torch.linspace(8.0, -0.5, OBSERVED)
    ds = torch.where(labels[:, None] > 0, closing[None, :], torch.full((1, OBSERVED), 20.0))
    edge = torch.zeros(n, OBSERVED, EDGE_DIM)
    edge[..., 0] = ds + 0.3 * torch.randn(n, OBSERVED)
    model = TGAT(TGATConfig())
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    for _ in range(40):
        loss = torch.nn.functional.binary_cross_entropy_with_logits(model(node_u, node_i, edge, mask)[0], labels)
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    probs = torch.sigmoid(model(node_u, node_i, edge, mask)[0]).detach().numpy()
    metrics = binary_metrics(labels.numpy(), probs, 0.5)
    assert metrics["auc"] > 0.95 and metrics["accuracy"] > 0.9


class _Fixed(torch.nn.Module):
    """A stand-in model with given outputs (and one parameter, for the loss's graph)."""

    def __init__(self, logits, ttc):
        super().__init__()
        self.logits, self.ttc = torch.tensor(logits), torch.tensor(ttc)
        self.w = torch.nn.Parameter(torch.ones(()))

    def forward(self, node_u, node_i, edge, mask):
        return self.logits[: len(node_u)] * self.w, self.ttc[: len(node_u)] * self.w


def _window_batch(labels, ttc):
    n = len(labels)
    return [torch.zeros(n, NODE_DIM), torch.zeros(n, NODE_DIM), torch.zeros(n, OBSERVED, EDGE_DIM),
            torch.ones(n, OBSERVED, dtype=torch.bool), torch.tensor(labels), torch.tensor(ttc)]


def _smooth_l1(x):
    x = abs(x)
    return 0.5 * x * x if x < 1.0 else x - 0.5


def test_training_loss_is_bce_plus_weighted_smooth_l1_on_positives():
    from riskmap.guard.train import training_loss

    logits, predicted = [1.5, -0.5, 0.2, -2.0], [0.4, 2.0, 1.1, 7.0]
    labels, ttc = [1.0, 1.0, 0.0, 0.0], [0.9, 0.3, float("inf"), 4.0]
    model = _Fixed(logits, predicted)
    batch = _window_batch(labels, ttc)
    bce = np.mean([-(y * np.log(1 / (1 + np.exp(-z))) + (1 - y) * np.log(1 - 1 / (1 + np.exp(-z))))
                   for z, y in zip(logits, labels)])
    l1 = np.mean([_smooth_l1(p - t) for p, t, y in zip(predicted, ttc, labels) if y])
    for weight in (0.0, 0.5, 2.0):
        loss = training_loss(model, batch, weight)
        assert float(loss.detach()) == pytest.approx(bce + weight * l1, rel=1e-6), weight
        assert torch.isfinite(loss)
    # no positive in the batch: the BCE alone (the negatives' inf time to contact is never used)
    neg = _window_batch([0.0, 0.0], [float("inf"), 3.5])
    bce_neg = np.mean([np.log1p(np.exp(z)) for z in logits[:2]])
    assert float(training_loss(model, neg, 1.0).detach()) == pytest.approx(bce_neg, rel=1e-6)


def test_evaluate_reports_the_time_to_contact_error_on_positives():
    from riskmap.guard.train import evaluate

    logits, predicted = [2.0, 1.0, -1.0, -3.0], [0.5, 2.5, 9.0, 0.1]
    labels, ttc = [1.0, 1.0, 0.0, 0.0], [1.0, 1.5, float("inf"), 3.5]
    metrics = evaluate(_Fixed(logits, predicted), tuple(_window_batch(labels, ttc)), threshold=0.6)
    assert metrics["ttc_mae_s"] == pytest.approx((0.5 + 1.0) / 2)
    assert metrics["at_alert_threshold"]["threshold"] == 0.6
    none = evaluate(_Fixed(logits, predicted), tuple(_window_batch([0.0] * 4, [float("inf")] * 4)))
    assert none["ttc_mae_s"] is None


def test_binary_metrics_hand_computed():
    labels = np.array([0, 0, 1, 1])
    probs = np.array([0.1, 0.7, 0.4, 0.9])
    m = binary_metrics(labels, probs, 0.5)
    assert m["auc"] == 0.75                       # 3 of 4 (pos, neg) pairs ranked right
    assert math.isclose(m["ap"], (1.0 + 2 / 3) / 2)
    assert m["accuracy"] == 0.5 and m["f1"] == 0.5
    assert binary_metrics(np.zeros(3), np.zeros(3), 0.5)["ap"] is None


def test_closest_approach_matches_a_float64_reference():
    """Distance and time of the constant-velocity closest approach within the horizon, per event."""
    import numpy as np

    config = TGATConfig(horizon_s=3.0, closest_approach=True)
    model = TGAT(config)
    rng = np.random.default_rng(0)
    edge = rng.normal(0.0, 15.0, size=(64, OBSERVED, EDGE_DIM))
    edge[0, 0, 1:] = [20.0, 0.0, -10.0, 0.0]     # head-on: closest at t = 2 s, distance 0
    edge[0, 1, 1:] = [20.0, 0.0, 10.0, 0.0]      # separating: closest now, 20 m
    edge[0, 2, 1:] = [60.0, 3.0, -10.0, 0.0]     # beyond the horizon: t = 3 s, 30 m ahead still
    got = model._closest_approach(torch.from_numpy(edge).float()).double().numpy()
    dp, dv = edge[..., 1:3], edge[..., 3:5]
    want_t = np.empty(edge.shape[:2])
    want_d = np.empty(edge.shape[:2])
    for b in range(edge.shape[0]):
        for j in range(OBSERVED):
            times = np.linspace(0.0, 3.0, 30001)                 # brute force over the horizon
            d = np.linalg.norm(dp[b, j] + times[:, None] * dv[b, j], axis=1)
            want_t[b, j], want_d[b, j] = times[np.argmin(d)], d.min()
    np.testing.assert_allclose(got[..., 1] * 3.0, want_t, atol=2e-3)
    np.testing.assert_allclose(got[..., 0] * 20.0, np.minimum(want_d, 100.0), atol=2e-3)
    assert got[0, 0, 1] * 3.0 == pytest.approx(2.0, abs=1e-4) and got[0, 0, 0] == pytest.approx(0.0, abs=1e-4)
    assert got[0, 1, 1] == 0.0 and got[0, 1, 0] * 20.0 == pytest.approx(20.0, abs=1e-3)
    assert got[0, 2, 1] * 3.0 == pytest.approx(3.0) and got[0, 2, 0] * 20.0 == pytest.approx(np.hypot(30.0, 3.0), abs=1e-3)


def test_closest_approach_changes_the_input_width_and_the_scores():
    import numpy as np

    torch.manual_seed(0)
    plain, with_ca = TGAT(TGATConfig()), TGAT(TGATConfig(closest_approach=True))
    assert with_ca.layers[0].edge_dim == plain.layers[0].edge_dim + 2
    b = 8
    rng = np.random.default_rng(1)
    edge = torch.from_numpy(rng.normal(0, 10, size=(b, OBSERVED, EDGE_DIM))).float()
    node = torch.from_numpy(rng.normal(size=(b, NODE_DIM))).float()
    mask = torch.ones(b, OBSERVED, dtype=torch.bool)
    with_ca.eval()
    before, _ = with_ca(node, node, edge, mask)
    moved = edge.clone()
    moved[..., 3:5] *= -1.0                                     # reversed relative velocities
    after, _ = with_ca(node, node, moved, mask)
    assert not torch.allclose(before, after)
