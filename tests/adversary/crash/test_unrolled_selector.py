"""The selector trained through the unrolled generation loss (`--objective unrolled`): the loss is
the generator's, its gradient reaches the selector through the unroll, training lowers it, and the
option reaches the checkpoint's sidecar."""

import itertools
import json

import numpy as np
import pytest
import torch

from adversary.cli import build_parser, main
from adversary.crash.batch import collate
from adversary.crash.config import TrainSelectorConfig
from adversary.crash.features import scene_tensors
from adversary.crash.generate import (
    GenerationConfig,
    _discs,
    adversary_of,
    attack_loss,
    collision_penalty,
    logged_ego_future,
)
from adversary.crash.selection import SelectionModule, candidates
from adversary.crash.traffic_model import TrafficModel, TrafficModelConfig
from adversary.crash.unrolled import unroll, unrolled_loss
from rasterize.errors import InputError
from rasterize.scene import Scene
from riskmap.infra.checkpoint import read_sidecar
from riskmap.infra.cli import config_from_args
from tests.scenes import state, straight_lane

TRAFFIC = "checkpoints/crash_traffic_highway"
HIDDEN = 16
ETA = 0.01          # this random model's loss is steep (its decoder drives far off the road)


def _scene(ahead_m: float, left_m: float) -> Scene:
    """Three lanes along +x; the ego at 20 m/s in the middle lane, one car `ahead_m` ahead in the
    same lane, one `left_m` ahead in the left lane, one 20 m behind on the right; 0.5 s steps."""
    t = (np.arange(17) - 4) * 0.5
    starts = [(100.0, 0.0), (100.0 + ahead_m, 0.0), (100.0 + left_m, 4.0), (80.0, -4.0)]
    states = np.array([[state(x0 + 20.0 * ti, y0, 0.0, 20.0) for ti in t] for x0, y0 in starts])
    lanes = tuple(straight_lane(y, x0=0.0, x1=400.0) for y in (-4.0, 0.0, 4.0))
    return Scene(states, np.ones(states.shape[:2], bool), sizes=np.tile([[5.0, 2.0]], (4, 1)),
                 kinds=np.zeros(4), ego_index=0, current_index=4, dt=0.5, lanes=lanes)


@pytest.fixture(scope="module")
def tiny():
    """A small random traffic model (frozen) and a batch of two scenes (3 and 4 agents after
    padding differences are none here, so one scene is cut to 3 agents to exercise padding)."""
    torch.manual_seed(0)
    model = TrafficModel(TrafficModelConfig(hidden=HIDDEN, latent=4, mixer_layers=1))
    for param in model.parameters():
        param.requires_grad_(False)
    items = [scene_tensors(_scene(15.0, 10.0)), scene_tensors(_scene(30.0, 8.0))]
    return model, collate(items)


def _selector(seed: int = 1) -> SelectionModule:
    torch.manual_seed(seed)
    return SelectionModule(HIDDEN)


def test_collision_penalty_is_twice_differentiable_at_coincident_discs():
    # A disc's distance to itself is 0: with |d| the second derivative is NaN, which every
    # unrolled step would spread into the selector's gradient.
    traj = torch.zeros(1, 2, 3, 4, dtype=torch.float64)
    traj[0, 1, :, 0] = torch.tensor([0.0, 1.0, 30.0])         # overlapping, touching, apart
    traj.requires_grad_(True)
    sizes = torch.tensor([[[4.5, 2.0], [4.5, 2.0]]], dtype=torch.float64)
    pairs = torch.ones(1, 2, 2, dtype=torch.bool) & ~torch.eye(2, dtype=torch.bool)[None]
    penalty = collision_penalty(traj, sizes, pairs)
    (grad,) = torch.autograd.grad(penalty.sum(), traj, create_graph=True)
    (second,) = torch.autograd.grad(grad.pow(2).sum(), traj)
    assert torch.isfinite(second).all() and penalty.item() > 0
    # ... and the smoothing leaves the value what |d| gives (reference: plain float64 norms).
    centres, radius = _discs(traj.detach(), sizes)
    plain = 0.0
    for t in range(3):
        d = (centres[0, 0, t][:, None] - centres[0, 1, t][None]).norm(dim=-1)
        plain += float(torch.relu(radius[0, 0] + radius[0, 1] - d).max())
    assert penalty.item() == pytest.approx(plain, abs=1e-5)      # eps = 1e-6 m per coincident pair


def test_gradient_reaches_every_selector_parameter_through_the_unroll(tiny):
    model, batch = tiny
    selector = _selector()
    logit_grads = []        # dloss/dlogits, to size the rounding of the shared bias's gradient

    def keep_logit_grads(module, inputs, output) -> None:
        output.register_hook(lambda g: logit_grads.append(g.abs().sum()))

    selector.adv_head.register_forward_hook(keep_logit_grads)
    loss, p = unrolled_loss(model, batch, selector, mam=False, steps=3, eta=ETA)
    loss.sum().backward()
    for name, param in selector.named_parameters():
        assert param.grad is not None and torch.isfinite(param.grad).all(), name
        if name == "adv_head.2.bias":
            # One bias added to every agent's logit before the softmax leaves p unchanged: its
            # gradient, the sum of the logits' gradients, is zero exactly. In float32 that sum
            # keeps rounding of the order of eps × the logits' gradients (seen: 8e-6 on one CPU).
            scale = float(sum(logit_grads))
            assert scale > 0 and param.grad.abs().sum() <= 1e-4 * scale, (name, param.grad, scale)
            continue
        assert param.grad.abs().sum() > 0, name
    through = [param.grad.clone() for param in selector.parameters()]

    # The same loss with z_K cut off from p: only the direct path (p in the final loss) is left.
    # The unroll must change the gradient, i.e. p also acts through the steps it shaped.
    selector.zero_grad()
    with torch.no_grad():
        enc = model.encode(batch)
        z_init, _ = model.posterior_of(batch, enc)
    p = selector(enc.context, candidates(batch, mam=False))
    ego = logged_ego_future(batch)
    z = unroll(model, batch, enc, z_init, p, ego, 3, ETA, GenerationConfig()).detach()
    direct, _, _ = attack_loss(model, batch, enc, z, z_init, p, adversary_of(p), ego, GenerationConfig())
    torch.testing.assert_close(direct, loss.detach(), rtol=1e-5, atol=1e-4)    # same value
    direct.sum().backward()
    differences = [(a - param.grad).abs().max() for a, param in zip(through, selector.parameters())]
    assert max(differences) > 1e-6


def test_the_ego_latent_never_moves_and_steps_lower_the_loss(tiny):
    model, batch = tiny
    with torch.no_grad():
        enc = model.encode(batch)
        z_init, _ = model.posterior_of(batch, enc)
        p = _selector()(enc.context, candidates(batch, mam=False))
    ego = logged_ego_future(batch)
    z = unroll(model, batch, enc, z_init, p, ego, 4, ETA, GenerationConfig())
    torch.testing.assert_close(z[:, 0], z_init[:, 0])
    config = GenerationConfig()
    before, _, _ = attack_loss(model, batch, enc, z_init, z_init, p, adversary_of(p), ego, config)
    after, _, _ = attack_loss(model, batch, enc, z, z_init, p, adversary_of(p), ego, config)
    assert (after < before).all()


def test_a_few_training_steps_lower_the_unrolled_loss(tiny):
    model, batch = tiny
    selector = _selector()
    optimiser = torch.optim.Adam(selector.parameters(), lr=5e-2)
    losses, ps = [], []
    for _ in range(12):
        loss, p = unrolled_loss(model, batch, selector, mam=False, steps=2, eta=ETA)
        optimiser.zero_grad()
        loss.mean().backward()
        optimiser.step()
        losses.append(loss.mean().item())
        ps.append(p.detach())
    # Most of this loss (the random decoder's off-road driving) does not depend on p; the part
    # that does falls, and p leaves the uniform start for one agent per scene.
    assert losses[-1] < losses[0] - 30.0 and all(b <= a + 1e-3 for a, b in itertools.pairwise(losses)), losses
    assert (ps[-1].max(-1).values > 0.6).all() and (ps[0].max(-1).values < 0.4).all()


def test_objective_option_parses_and_is_validated(tmp_path):
    base = ["train-selector", "--traffic-model", TRAFFIC, "--data", "d", "--out", str(tmp_path / "o")]
    args = build_parser().parse_args(base + ["--objective", "unrolled", "--unroll-steps", "3",
                                             "--unroll-lr", "0.1"])
    config = config_from_args(TrainSelectorConfig, args)
    assert (config.objective, config.unroll_steps, config.unroll_lr) == ("unrolled", 3, 0.1)
    assert config_from_args(TrainSelectorConfig, build_parser().parse_args(base)).objective == "labels"
    with pytest.raises(SystemExit):
        build_parser().parse_args(base + ["--objective", "gradient"])
    with pytest.raises(InputError, match="--unroll-lr"):
        TrainSelectorConfig(objective="unrolled", unroll_lr=0.0)


def test_unrolled_run_writes_the_objective_into_the_sidecars_and_resumes(tmp_path, capsys):
    from riskmap.data.collect import CollectConfig, collect

    data = tmp_path / "data"
    collect(CollectConfig("highway-v0", episodes=2, seed=3), data, progress=False)
    out = tmp_path / "run"
    argv = ["train-selector", "--traffic-model", TRAFFIC, "--data", str(data), "--max-scenes", "5",
            "--windows-per-episode", "3", "--label-iterations", "2", "--epochs", "2", "--objective",
            "unrolled", "--unroll-steps", "2", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    for name, mam in (("selector_mam", True), ("selector_no_mam", False)):
        sidecar = read_sidecar(out / name, kind="crash_selector")
        assert sidecar["mam"] is mam and sidecar["objective"] == "unrolled" and sidecar["unroll_steps"] == 2
    summary = json.loads((out / "summary.json").read_text())
    assert summary["objective"] == "unrolled" and summary["selector_mam"]["val_unrolled_loss"] is not None
    weights = (out / "selector_mam.safetensors").read_bytes()
    # A finished run resumed trains nothing more and commits the same selector; other settings refused.
    assert main(argv + ["--resume"]) == 0
    assert (out / "selector_mam.safetensors").read_bytes() == weights
    capsys.readouterr()
    assert main([a if a != "unrolled" else "labels" for a in argv] + ["--resume"]) != 0
    assert "other train-selector settings" in capsys.readouterr().err
