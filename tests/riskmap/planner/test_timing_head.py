"""The timing head: arc lengths learned from the demonstrations' futures, and the planner timing
its path by them."""

import json

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from rasterize.config import Extent, GridConfig
from rasterize.errors import InputError
from riskmap.data.dataset import DemoDataset
from riskmap.planner.model import (
    ModelConfig,
    RiskMapGenerator,
    TimingHead,
    demo_arc_lengths,
    timing_loss,
)
from riskmap.planner.riskmap_planner import RiskMapPlanner
from riskmap.planner.sampler import SamplerConfig, retime
from riskmap.training.train import train
from tests.riskmap.conftest import tiny_train_config


def test_a_fresh_head_holds_the_present_speed_and_never_goes_backwards():
    torch.manual_seed(0)
    head = TimingHead(channels=8)
    features, speed = torch.rand(3, 8, 20, 20), torch.tensor([0.5, 12.0, 31.0])
    arcs = head(features, speed).double()
    expected = speed.double()[:, None] * 0.5 * torch.arange(1, 13, dtype=torch.float64)
    torch.testing.assert_close(arcs, expected, rtol=1e-5, atol=1e-5)
    for layer in head.mlp:                      # any weights: speeds are never negative
        if isinstance(layer, torch.nn.Linear):
            torch.nn.init.normal_(layer.weight, std=1.0)
    arcs = head(features, speed)
    assert (arcs.diff(dim=1) >= 0).all() and (arcs[:, 0] >= 0).all()


def test_demonstration_arc_lengths_are_the_polyline_from_the_ego():
    future = torch.tensor([[[3.0, 4.0], [3.0, 4.0], [6.0, 8.0]] + [[6.0, 8.0]] * 9], dtype=torch.float64)
    by_hand = np.array([5.0, 5.0, 10.0] + [10.0] * 9)
    np.testing.assert_allclose(demo_arc_lengths(future)[0].numpy(), by_hand)
    assert timing_loss(torch.tensor(by_hand)[None], future).item() == 0.0
    # Huber with a 1 m knee: 0.5 m off is quadratic, 3 m off linear.
    off = torch.tensor(by_hand)[None] + torch.tensor([0.5] + [3.0] + [0.0] * 10)
    assert timing_loss(off, future).item() == pytest.approx((0.5 * 0.25 + 2.5) / 12)


# 1 m cells whose centres fall on whole metres: the ego (the origin) at the centre of (100, 10).
GRID = GridConfig(Extent(100.5, 9.5, 10.5, 9.5), rows=110, cols=20)


def test_learned_arc_lengths_place_the_waypoints_along_the_path_and_stop_at_its_end():
    # A straight path from the ego's cell 40 cells (40 m) ahead.
    start = np.array([100, 10])
    path = np.array([start - [k, 0] for k in range(41)])
    arcs = np.array([1.0, 3.0, 2.0, 6.0, 10.0, 15.0, 21.0, 28.0, 36.0, 45.0, 55.0, 66.0])
    waypoints = retime(path, 40, GRID, 20.0, SamplerConfig(timing="learned"), arc_lengths=arcs)
    np.testing.assert_allclose(waypoints[:, 1], 0.0, atol=1e-12)
    along = waypoints[:, 0]
    # Never backwards (3 then 2 holds at 3), never beyond the path's 40 m.
    np.testing.assert_allclose(along, [1, 3, 3, 6, 10, 15, 21, 28, 36, 40, 40, 40], atol=1e-9)


def test_fine_tuning_adds_a_head_to_a_trained_network_and_freeze_risk_keeps_its_risk_map(
        tiny_dataset, tiny_checkpoint, tmp_path):
    out = tmp_path / "head"
    train(tiny_train_config(tiny_dataset, out, epochs=3, init_checkpoint=str(tiny_checkpoint),
                            timing_head=True, freeze_risk=True), progress=False)
    before, after = load_file(str(tiny_checkpoint.with_suffix(".safetensors"))), \
        load_file(str(out / "last.safetensors"))
    assert {k for k in after if k.startswith("timing.")} and set(after) - set(before) == \
        {k for k in after if k.startswith("timing.")}
    for key in before:                           # batch-norm statistics included
        torch.testing.assert_close(after[key], before[key], rtol=0, atol=0)
    side = json.loads((out / "last.json").read_text())
    assert side["sampler"]["timing"] == "learned" and side["model"]["timing_head"]
    log = (out / "log.csv").read_text().splitlines()
    header, rows = log[0].split(","), [dict(zip(log[0].split(","), r.split(","))) for r in log[1:]]
    assert "train_timing" in header and "val_timing_m" in header
    assert float(rows[-1]["train_timing"]) < float(rows[0]["train_timing"])
    # The planner times its path by the head: waypoints advance as the head says.
    planner = RiskMapPlanner.load(out / "last")
    scene = DemoDataset(tiny_dataset).scene(0)
    plan = planner.plan(scene)
    assert plan.waypoints.shape == (12, 2) and np.isfinite(plan.waypoints).all()
    # A run without a head refuses to start from a network with one (it would drop the head).
    with pytest.raises(InputError, match="--timing-head"):
        train(tiny_train_config(tiny_dataset, tmp_path / "back", init_checkpoint=str(out / "last")),
              progress=False)


def test_learned_timing_is_refused_for_a_network_without_a_head(tiny_checkpoint, tmp_path):
    side = json.loads(tiny_checkpoint.with_suffix(".json").read_text())
    side["planning"] = {**side.get("planning", {}), "timing": "learned"}
    (tmp_path / "c.json").write_text(json.dumps(side))
    (tmp_path / "c.safetensors").write_bytes(tiny_checkpoint.with_suffix(".safetensors").read_bytes())
    with pytest.raises(InputError, match="no timing head"):
        RiskMapPlanner.load(tmp_path / "c")
    with pytest.raises(InputError, match="--timing-head"):
        RiskMapGenerator(ModelConfig(resolution=25)).forward_timed(torch.zeros(1, 8, 200, 200),
                                                                   torch.zeros(1, 3, 25, 25))


def test_freeze_risk_needs_a_head_and_a_checkpoint(tiny_dataset, tmp_path):
    with pytest.raises(InputError, match="--freeze-risk"):
        tiny_train_config(tiny_dataset, tmp_path / "x", timing_head=True, freeze_risk=True)


def test_the_planner_follows_the_heads_arc_lengths(tiny_dataset, tiny_checkpoint, tmp_path):
    """With the head's last layer set to a constant output, every plan covers exactly the arc
    lengths that output means (where the path is long enough)."""
    out = tmp_path / "head"
    train(tiny_train_config(tiny_dataset, out, epochs=1, init_checkpoint=str(tiny_checkpoint),
                            timing_head=True, freeze_risk=True), progress=False)
    planner = RiskMapPlanner.load(out / "last")
    last = planner.model.timing.mlp[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.fill_(-1.0)                 # every step much slower than the present speed
    scene = DemoDataset(tiny_dataset).scene(3)
    speed = float(scene.past().ego_state()[4])
    v = max(speed, 0.1)
    held = v + np.log(-np.expm1(-v))
    step_speed = np.log1p(np.exp(-30.0 + held))
    expected = 0.5 * step_speed * np.arange(1, 13)
    plan = planner.plan(scene)
    along = np.cumsum(np.linalg.norm(np.diff(np.vstack([[0, 0], plan.waypoints]), axis=0), axis=1))
    assert expected[-1] < 1e-6                 # the head says: stand still
    assert along[-1] < 1e-6
