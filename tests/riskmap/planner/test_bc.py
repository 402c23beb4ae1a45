import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from rasterize.errors import InputError
from riskmap.cli import main
from riskmap.planner.bc import BCConfig, BCNet, _frame_scenes, bc_inputs
from riskmap.registry import make_planner
from riskmap.sim.loop.plan import Planner
from tests.scenes import UNIT_RASTER, constant_velocity_scene, straight_lane


def _scene():
    scene = constant_velocity_scene(n_past=2, n_future=4, ego_speed=2.0, lanes=[straight_lane(0.0)])
    return replace(scene, route_xy=np.array([[0.0, 0.0], [6.0, 0.0]]))


@pytest.mark.parametrize("kind,frames,channels", [("cnn", 1, 8), ("cnn_lstm", 3, 8), ("rvsg", 1, 9)])
def test_inputs_and_output_shapes(kind, frames, channels):
    config = BCConfig(kind=kind, history_frames=3, goal_resolution=20)
    x, speed = bc_inputs(_scene(), config, UNIT_RASTER)
    assert x.shape == (frames, channels, 20, 20) and x.dtype == np.float32
    assert 0.0 <= x.min() and x.max() <= 1.0
    np.testing.assert_allclose(speed, 2.0)
    out = BCNet(config)(torch.from_numpy(x)[None], torch.from_numpy(speed)[None])
    assert out.shape == (1, 12, 2) and torch.isfinite(out).all()


def test_rvsg_goal_channel_peaks_at_the_route_goal():
    x, _ = bc_inputs(_scene(), BCConfig(kind="rvsg", goal_resolution=20), UNIT_RASTER)
    # Goal 6 m ahead on the ego's line: 1 m pixels, row 0 is x in (9, 10], so x = 6 is row 3-4.
    row, col = np.unravel_index(np.argmax(x[0, -1]), x[0, -1].shape)
    assert row in (3, 4) and col in (9, 10)


def test_head_is_an_offset_from_constant_velocity():
    net = BCNet(BCConfig(kind="cnn"))
    torch.nn.init.zeros_(net.head.weight)
    torch.nn.init.zeros_(net.head.bias)
    out = net(torch.rand(2, 1, 8, 16, 16), torch.tensor([[0.0], [4.0]]))
    t = 0.5 * np.arange(1, 13)
    np.testing.assert_allclose(out[0].detach().numpy(), 0.0, atol=1e-6)
    np.testing.assert_allclose(out[1, :, 0].detach().numpy(), 4.0 * t, rtol=1e-6)
    np.testing.assert_allclose(out[1, :, 1].detach().numpy(), 0.0, atol=1e-6)


def test_history_frames_repeat_the_oldest_when_the_record_is_short():
    scene = _scene()
    frames = _frame_scenes(scene, 4)      # wants t = -1.5 .. 0 s; the record starts at -1 s
    assert [f.current_index for f in frames] == [0, 0, 1, 2]
    assert all(f.num_steps == f.current_index + 1 for f in frames)   # never the future


def test_unknown_kind():
    with pytest.raises(InputError, match="cnn_lstm"):
        BCConfig(kind="transformer")


def test_train_baseline_cli_resumes_and_ships_a_planner(tiny_dataset, tmp_path):
    out = tmp_path / "lstm"
    args = ["train-baseline", "cnn-lstm", "--data", str(tiny_dataset), "--out", str(out),
            "--epochs", "1", "--batch-size", "2", "--max-windows", "4", "--history-frames", "2",
            "--quiet"]
    assert main(args) == 0
    assert main(args) == 2                                  # refuses to overwrite without --resume
    assert main(args[:6] + ["--epochs", "2"] + args[8:] + ["--resume"]) == 0
    log = (out / "log.csv").read_text().splitlines()
    assert [row.split(",")[0] for row in log[1:]] == ["0", "1"]
    side = json.loads((out / "best.json").read_text())
    assert side["kind"] == "bc" and side["bc"]["kind"] == "cnn_lstm"
    planner = make_planner(f"cnn_lstm:{out / 'best'}")
    assert isinstance(planner, Planner)
    from riskmap.data.dataset import DemoDataset

    scene = DemoDataset(tiny_dataset).scene(0)
    plan = planner.plan(scene)
    assert plan.waypoints.shape == (12, 2) and np.isfinite(plan.waypoints).all()
    with pytest.raises(InputError, match="cnn_lstm baseline, not rvsg"):
        make_planner(f"rvsg:{out / 'best'}")
    with pytest.raises(InputError, match="not a risk-map planner one"):
        make_planner(f"riskmap:{out / 'best'}")
