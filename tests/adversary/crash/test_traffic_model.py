"""The traffic model's inputs, networks, selection and latent optimisation on hand-built scenes."""

import math

import numpy as np
import pytest
import torch

from adversary.crash.batch import collate, sample_field
from adversary.crash.features import FUTURE_STEPS, FeatureConfig, off_road_field, scene_tensors
from adversary.crash.generate import (
    GenerationConfig,
    attack_loss,
    collision_penalty,
    generate,
    logged_ego_future,
)
from adversary.crash.selection import (
    SelectionModule,
    candidates,
    distance_weights,
    nearest_weights,
    random_weights,
)
from adversary.crash.traffic_model import TrafficModel, TrafficModelConfig, kl_normal, log_normal
from rasterize.scene import Scene
from tests.scenes import state, straight_lane


def highway_scene(static_row: int | None = None) -> Scene:
    """A 3-lane road along +x; the ego at 20 m/s in the middle lane (y = 0) heading east at
    x = 100 m at t0, one car 15 m ahead in the same lane, one 10 m ahead in the left lane
    (y = 4), one 20 m behind in the right lane (y = -4); all at 20 m/s, 17 steps of 0.5 s."""
    t = (np.arange(17) - 4) * 0.5
    starts = [(100.0, 0.0), (115.0, 0.0), (110.0, 4.0), (80.0, -4.0)]
    states = []
    for i, (x0, y0) in enumerate(starts):
        speed = 0.0 if i == static_row else 20.0
        states.append([state(x0 + speed * ti, y0, 0.0, speed) for ti in t])
    states = np.array(states)
    lanes = tuple(straight_lane(y, x0=0.0, x1=400.0) for y in (-4.0, 0.0, 4.0))
    return Scene(states, np.ones(states.shape[:2], bool), sizes=np.tile([[5.0, 2.0]], (4, 1)),
                 kinds=np.zeros(4), ego_index=0, current_index=4, dt=0.5, lanes=lanes)


def test_scene_frame_rows_and_field():
    item = scene_tensors(highway_scene())
    assert item.rows.tolist() == [0, 2, 1, 3]          # the ego, then nearest first
    np.testing.assert_allclose(item.past[0, -1], [0, 0, 1, 0, 20], atol=1e-6)
    np.testing.assert_allclose(item.past[1, -1, :2], [10, 4], atol=1e-5)
    np.testing.assert_allclose(item.future[0, -1, :2], [120, 0], atol=1e-4)
    np.testing.assert_allclose(item.world_xy(item.future[0, -1:, :2]), [[220.0, 0.0]], atol=1e-4)
    assert item.chunks.shape == (4, 8, 8, 4) and item.chunk_valid.all()
    # Lane points are in each agent's own frame: the ego's lane centre runs through y = 0.
    assert np.abs(item.chunks[0, :, :, 1]).min() < 1e-5
    assert item.off_road.sample(np.array([[30.0, 0.0], [30.0, 5.9]])).max() == 0.0
    assert item.off_road.sample(np.array([30.0, 9.0])) >= 2.5


def test_off_road_field_against_hand_values():
    square = [np.array([[0, 0], [4, 0], [4, 2], [0, 2.0]])]
    field = off_road_field(square, np.array([-2.0, -2.0]), np.array([6.0, 4.0]), 0.5)
    # cell centres: x = 5.25 is 1.5 m from the last drivable centre x = 3.75
    np.testing.assert_allclose(field.sample(np.array([[1, 1], [5.1, 1], [1, 3.6]])), [0.0, 1.5, 2.0])
    batch = collate([scene_tensors(highway_scene())])
    inside = sample_field(batch, torch.tensor([[[50.0, 0.0], [50.0, 12.0]]]))
    assert inside[0, 0] == 0.0 and inside[0, 1] > 5.0


def test_motion_aware_masking_drops_static_agents_and_the_ego():
    batch = collate([scene_tensors(highway_scene(static_row=1))])
    item_rows = scene_tensors(highway_scene(static_row=1)).rows.tolist()
    static = item_rows.index(1)
    with_mam = candidates(batch, mam=True)[0].tolist()
    without = candidates(batch, mam=False)[0].tolist()
    assert without == [False, True, True, True]
    assert with_mam[static] is False and sum(with_mam) == 2 and with_mam[0] is False


def test_distance_selection_matches_a_float64_softmin_and_excludes_agents_behind():
    batch = collate([scene_tensors(highway_scene())])
    ego = logged_ego_future(batch)
    traj = torch.stack([ego[:, None].expand(-1, 4, -1, -1)[0, i] + torch.tensor([dx, dy, 0, 0])
                        for i, (dx, dy) in enumerate([(0, 0), (3, 4), (8, 0), (-20, -4)])])[None]
    mask = candidates(batch, mam=False)
    p = distance_weights(traj.float(), ego, batch, mask, temperature_m=2.0)[0].double()
    d = np.array([5.0, 8.0])                       # rows 1 and 2; row 3 is behind the ego
    w = np.exp(-d / 2.0) * FUTURE_STEPS
    np.testing.assert_allclose(p.numpy(), [0.0, w[0] / w.sum(), w[1] / w.sum(), 0.0], rtol=1e-5)
    assert nearest_weights(batch, mask)[0].tolist() == [0.0, 1.0, 0.0, 0.0]
    r = random_weights(mask, np.random.default_rng(0))[0]
    assert r.sum() == 1.0 and r[0] == 0.0


def test_selection_module_is_a_distribution_over_candidates_and_permutation_equivariant():
    torch.manual_seed(0)
    asm = SelectionModule(16, heads=4)
    z = torch.randn(1, 5, 16)
    mask = torch.tensor([[False, True, True, False, True]])
    p = asm(z, mask)
    assert torch.isclose(p.sum(), torch.tensor(1.0)) and p[0, 0] == 0 and p[0, 3] == 0
    perm = torch.tensor([0, 4, 2, 3, 1])
    np.testing.assert_allclose(asm(z[:, perm], mask[:, perm]).detach(), p[:, perm].detach(), atol=1e-6)
    assert asm(z, torch.zeros(1, 5, dtype=torch.bool)).sum() == 0.0


def test_gaussian_helpers_against_torch_distributions_in_float64():
    g = torch.Generator().manual_seed(1)
    mu_q, lv_q, mu_p, lv_p, z = (torch.randn(3, 4, generator=g, dtype=torch.float64) for _ in range(5))
    q = torch.distributions.Normal(mu_q, (0.5 * lv_q).exp())
    p = torch.distributions.Normal(mu_p, (0.5 * lv_p).exp())
    torch.testing.assert_close(kl_normal(mu_q, lv_q, mu_p, lv_p), torch.distributions.kl_divergence(q, p).sum(-1))
    torch.testing.assert_close(log_normal(z, mu_p, lv_p), p.log_prob(z).sum(-1))


def test_collision_penalty_is_zero_apart_and_positive_when_boxes_overlap():
    sizes = torch.tensor([[[5.0, 2.0], [5.0, 2.0]]])
    apart = torch.tensor([[[[0.0, 0.0, 0.0, 0.0]], [[0.0, 3.0, 0.0, 0.0]]]])     # 3 m side by side
    touching = torch.tensor([[[[0.0, 0.0, 0.0, 0.0]], [[4.0, 0.0, 0.0, 0.0]]]])  # 1 m bumper overlap
    pair = torch.tensor([[[False, True], [True, False]]])
    assert collision_penalty(apart, sizes, pair) == 0.0
    assert collision_penalty(touching, sizes, pair) > 0.5
    assert collision_penalty(touching, sizes, torch.zeros_like(pair)) == 0.0


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return TrafficModel(TrafficModelConfig(hidden=32, latent=8, mixer_layers=1)).eval()


def test_decoder_obeys_fixed_rows_and_never_reverses(model):
    batch = collate([scene_tensors(highway_scene()), scene_tensors(highway_scene(static_row=2))])
    enc = model.encode(batch)
    assert enc.context.shape == (2, 4, 32) and enc.prior_mu.shape == (2, 4, 8)
    z = torch.randn(2, 4, 8) * 3.0
    fixed = torch.zeros(2, 4, FUTURE_STEPS, 4)
    fixed[:, 0] = logged_ego_future(batch)
    mask = torch.zeros(2, 4, dtype=torch.bool)
    mask[:, 0] = True
    traj = model.decode(batch, enc, z, fixed, mask)
    torch.testing.assert_close(traj[:, 0], fixed[:, 0])
    assert (traj[..., 3] >= 0).all() and (traj[..., 3] <= model.config.max_speed_mps).all()
    # Kinematics: every displacement is at most the step's mean speed times 0.5 s.
    xy = torch.cat([enc.start[:, 1:, None, :2], traj[:, 1:, :, :2]], dim=2)
    v = torch.cat([enc.start[:, 1:, None, 3], traj[:, 1:, :, 3]], dim=2)
    step = (xy[:, :, 1:] - xy[:, :, :-1]).norm(dim=-1)
    assert (step <= 0.5 * 0.5 * (v[:, :, 1:] + v[:, :, :-1]) + 1e-4).all()


def test_generation_pulls_the_adversary_onto_the_ego(model):
    batch = collate([scene_tensors(highway_scene())])
    p = torch.tensor([[0.0, 0.0, 1.0, 0.0]])          # row 2: the car 15 m ahead, same lane
    ego = logged_ego_future(batch)
    with torch.no_grad():
        enc = model.encode(batch)
        z0, _ = model.posterior_of(batch, enc)
        before, traj0, _ = attack_loss(model, batch, enc, z0, z0, p, torch.tensor([2]), ego, GenerationConfig())
    gen = generate(model, batch, p, ego, GenerationConfig(iterations=60, lr=0.1, stop_on_collision=False))
    with torch.no_grad():
        after, traj, _ = attack_loss(model, batch, enc, gen.z, z0, p, gen.adversary, ego, GenerationConfig())
    assert gen.adversary.tolist() == [2] and gen.iterations == [60]
    assert float(after) < float(before)
    gap_before = (traj0[0, 2, :, :2] - ego[0, :, :2]).norm(dim=-1).mean()
    gap_after = (traj[0, 2, :, :2] - ego[0, :, :2]).norm(dim=-1).mean()
    assert gap_after < gap_before
    torch.testing.assert_close(gen.z[0, 0], z0[0, 0])   # the ego's latent is never moved


def test_feature_config_changes_agent_count():
    item = scene_tensors(highway_scene(), FeatureConfig(max_agents=2))
    assert item.num_agents == 2 and item.rows.tolist() == [0, 2]
    assert math.isclose(float(item.heading), 0.0)
