"""The traffic model's realism term (prior collisions / off-road in training), its settings and
flags, the family in its sidecar and the recorded-data validation split."""

import json
import math

import numpy as np
import pytest
import torch

from adversary.crash.batch import collate
from adversary.crash.config import TrainTrafficConfig
from adversary.crash.features import scene_tensors
from adversary.crash.generate import collision_penalty
from adversary.crash.traffic_model import TrafficModel, TrafficModelConfig
from adversary.crash.train_traffic import (
    CHECKPOINT_KIND,
    held_out,
    logged_off_road,
    logged_overlaps,
    realism_loss,
    traffic_model_family,
    train_traffic,
    training_loss,
)
from rasterize.errors import InputError
from rasterize.scene import Scene
from riskmap.infra.checkpoint import save_checkpoint
from tests.scenes import state, straight_lane


def convoy_scene(rear_crash: bool = False) -> Scene:
    """Five cars 7 m apart (centres) in one lane along +x at 15 m/s, the ego in the middle at
    x = 100 m at t0; 17 steps of 0.5 s, 4 of them past. With `rear_crash` the last car's logged
    future drives into the one ahead of it (16 m/s from t0 on: 6 m closer in 6 s)."""
    t = (np.arange(17) - 4) * 0.5
    starts = [100.0, 107.0, 93.0, 114.0, 86.0]
    states = []
    for i, x0 in enumerate(starts):
        rows = []
        for ti in t:
            speed = 16.0 if rear_crash and i == 4 and ti > 0 else 15.0
            rows.append(state(x0 + 15.0 * min(ti, 0.0) + speed * max(ti, 0.0), 0.0, 0.0, speed))
        states.append(rows)
    states = np.array(states)
    lanes = (straight_lane(0.0, x0=0.0, x1=400.0),)
    return Scene(states, np.ones(states.shape[:2], bool), sizes=np.tile([[5.0, 2.0]], (5, 1)),
                 kinds=np.zeros(5), ego_index=0, current_index=4, dt=0.5, lanes=lanes)


def _prior_overlap(model, batch, seed: int) -> float:
    """Mean disc overlap (m, summed over pairs and steps) of prior samples with fixed noise."""
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        enc = model.encode(batch)
        eps = torch.randn(enc.prior_mu.shape, generator=gen)
        traj = model.decode(batch, enc, enc.prior_mu + eps * (0.5 * enc.prior_logvar).exp())
        n = batch.agent_mask.shape[1]
        pair = batch.agent_mask[:, :, None] & batch.agent_mask[:, None, :] & ~torch.eye(n, dtype=torch.bool)
        return float(collision_penalty(traj, batch.sizes, pair).mean())


def test_realism_term_is_differentiable_and_lowers_prior_overlap():
    torch.manual_seed(0)
    model = TrafficModel(TrafficModelConfig(hidden=32, latent=8, mixer_layers=1))
    batch = collate([scene_tensors(convoy_scene())] * 16)      # 16 prior draws of one scene
    assert not logged_overlaps(batch).any()                   # the log keeps its gaps
    before = _prior_overlap(model, batch, seed=1)
    assert before > 1.0                                       # random decoders crash the convoy
    loss, parts = realism_loss(model, batch, model.encode(batch), collision_weight=1.0, off_road_weight=0.0)
    loss.backward()
    grads = [p.grad for p in model.prior.parameters()] + [p.grad for p in model.decoder.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert sum(float(g.abs().sum()) for g in grads) > 0       # through the reparameterised sample
    assert parts["prior_collision"] > 0
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)
    for _ in range(30):
        loss, _ = realism_loss(model, batch, model.encode(batch), collision_weight=1.0, off_road_weight=0.0)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    after = _prior_overlap(model, batch, seed=1)
    assert after < 0.3 * before, (before, after)


def test_logged_crashes_and_off_road_agents_are_left_out():
    crash = collate([scene_tensors(convoy_scene(rear_crash=True))])
    rows = scene_tensors(convoy_scene(rear_crash=True)).rows.tolist()
    rear, ahead = rows.index(4), rows.index(2)                 # x = 86 m runs into x = 93 m
    overlaps = logged_overlaps(crash)[0]
    assert overlaps[rear, ahead] and overlaps[ahead, rear]
    assert int(overlaps.sum()) == 2                            # that pair only, never an agent with itself
    assert not logged_off_road(crash).any()
    # The same scene without the crash: a prior that reproduces the log exactly is penalised
    # only where the log itself is clean.
    torch.manual_seed(0)
    model = TrafficModel(TrafficModelConfig(hidden=32, latent=8, mixer_layers=1))
    loss, parts = training_loss(model, crash, 0.05, 2.0, collision_weight=1.0, off_road_weight=1.0)
    assert math.isfinite(float(loss.detach())) and {"prior_collision", "prior_off_road"} <= set(parts)
    _, plain = training_loss(model, crash, 0.05, 2.0)
    assert set(plain) == {"recon", "kl"}


def test_off_road_of_logged_futures():
    scene = convoy_scene()
    shifted = scene.states.copy()
    shifted[3, 5:, 1] = 12.0                                    # row 3 jumps 12 m off its 4 m lane
    item = collate([scene_tensors(Scene(shifted, scene.valid, scene.sizes, scene.kinds, 0, 4, 0.5,
                                        lanes=scene.lanes))])
    rows = scene_tensors(Scene(shifted, scene.valid, scene.sizes, scene.kinds, 0, 4, 0.5, lanes=scene.lanes)).rows
    off = logged_off_road(item)[0].tolist()
    assert off == [r == 3 for r in rows.tolist()]


@pytest.mark.parametrize("field", ["prior_collision_weight", "prior_off_road_weight"])
@pytest.mark.parametrize("value", [-0.1, float("nan"), float("inf")])
def test_config_refuses_bad_weights(field, value):
    with pytest.raises(InputError, match="--" + field.replace("_", "-")):
        TrainTrafficConfig(**{field: value})


def test_config_defaults_keep_the_old_training():
    config = TrainTrafficConfig()
    assert config.prior_collision_weight == 0.0 and config.prior_off_road_weight == 0.0
    assert TrainTrafficConfig(prior_collision_weight=2.5, prior_off_road_weight=0.0).prior_collision_weight == 2.5


def test_cli_flags_parse():
    from adversary.cli import build_parser
    from riskmap.infra.cli import config_from_args

    args = build_parser().parse_args(["train-traffic", "--data", "d", "--out", "o", "--prior-collision-weight",
                                      "1.5", "--prior-off-road-weight", "0.25"])
    config = config_from_args(TrainTrafficConfig, args)
    assert config.prior_collision_weight == 1.5 and config.prior_off_road_weight == 0.25
    plain = config_from_args(TrainTrafficConfig, build_parser().parse_args(["train-traffic", "--data", "d",
                                                                            "--out", "o"]))
    assert plain == TrainTrafficConfig()
    with pytest.raises(InputError, match="--prior-off-road-weight"):
        config_from_args(TrainTrafficConfig, build_parser().parse_args(
            ["train-traffic", "--data", "d", "--out", "o", "--prior-off-road-weight", "-1"]))


def test_family_of_old_and_new_sidecars(tmp_path):
    model = TrafficModel(TrafficModelConfig(hidden=16, latent=4, mixer_layers=1))
    save_checkpoint(tmp_path / "old", model, {"model": {}}, kind=CHECKPOINT_KIND)
    save_checkpoint(tmp_path / "new", model, {"model": {}, "family": "intersection"}, kind=CHECKPOINT_KIND)
    assert traffic_model_family(tmp_path / "old") is None
    assert traffic_model_family(tmp_path / "new") == "intersection"
    with pytest.raises(InputError):
        traffic_model_family(tmp_path / "missing")


def test_shipped_sidecars_name_their_family():
    from pathlib import Path

    root = Path(__file__).resolve().parents[3] / "checkpoints"
    for family in ("highway", "intersection"):
        assert traffic_model_family(root / f"crash_traffic_{family}") == family


class _Recorded:
    """A stand-in for a recorded dataset: window -> (episode, group)."""

    def __init__(self, windows: list[tuple[int, str | None]]):
        self.windows = windows

    def __len__(self):
        return len(self.windows)

    def episode_of(self, i):
        return self.windows[i][0]

    def group_of(self, i):
        return self.windows[i][1]


def test_recorded_data_validates_on_whole_groups():
    # groups X-2 (4 windows, episodes 0-1), X-10 (1 window), X-13 (5 windows): natural order
    # 2 < 10 < 13; 20% of 10 windows = 2: X-13 is too big, X-10 validates, X-2 always trains.
    data = _Recorded([(0, "X-2"), (0, "X-2"), (1, "X-2"), (1, "X-2"), (2, "X-10")] + [(3, "X-13")] * 5)
    assert held_out(data, 0.2) == {2}
    assert held_out(data, 0.0) == set()
    # Simulated episodes (no groups): the last share of the episodes.
    sim = _Recorded([(e, None) for e in range(10)])
    assert held_out(sim, 0.2) == {8, 9}
    # One recorded group: nothing to hold out whole, so by episodes too.
    assert held_out(_Recorded([(e, "X-1") for e in range(10)]), 0.2) == {8, 9}


def test_train_traffic_on_recorded_windows_records_the_family(tmp_path):
    """End to end on the recorded US-101 fixture files: collection, a short training with the
    realism term, the family and extent in the sidecar, --resume with the new settings."""
    from pathlib import Path

    from riskmap.data.collect_commonroad import collect_commonroad

    fixtures = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"
    data = tmp_path / "data"
    collect_commonroad(sorted(fixtures.glob("USA_US101-*_T-1.xml")), data, progress=False)
    torch.set_num_threads(1)
    config = TrainTrafficConfig(epochs=1, batch_size=8, max_windows_per_episode=2, val_fraction=0.5,
                                prior_collision_weight=1.0, prior_off_road_weight=0.1)
    out = tmp_path / "run"
    summary = train_traffic([data], out, config, model_config=TrafficModelConfig(hidden=16, latent=4,
                                                                                 mixer_layers=1),
                            progress=False)
    assert summary["family"] == "us101" and summary["sources"] == ["commonroad"]     # the attack's name
    assert summary["val_scenes"] > 0 and summary["train_scenes"] > 0
    assert traffic_model_family(out / "best") == "us101"
    side = json.loads((out / "best.json").read_text())
    assert side["extent"] == json.loads((data / "manifest.json").read_text())["config"]["raster"]["extent"]
    log = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    assert "train_prior_collision" in log[0] and math.isfinite(log[0]["train_prior_off_road"])
    resumed = train_traffic([data], out, TrainTrafficConfig(**{**config.__dict__, "epochs": 2}),
                            model_config=TrafficModelConfig(hidden=16, latent=4, mixer_layers=1),
                            resume=True, progress=False)
    assert len((out / "log.jsonl").read_text().splitlines()) == 2 and resumed["family"] == "us101"


def test_train_traffic_refuses_mixed_families(tmp_path):
    from adversary.crash.train_traffic import data_family

    for name, env in (("a", "highway-v0"), ("b", "intersection-v0")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "manifest.json").write_text(json.dumps({"config": {"env_id": env}}))
    assert data_family([tmp_path / "a"])["family"] == "highway"
    with pytest.raises(InputError, match="mixes scenario families"):
        data_family([tmp_path / "a", tmp_path / "b"])



def test_rates_at_logged_steps_never_exceed_those_over_every_step():
    from adversary.crash.train_traffic import evaluate_model

    scene = convoy_scene()
    valid = scene.valid.copy()
    valid[3, 8:] = False                      # row 3 leaves the log 2 s into the future
    items = [scene_tensors(convoy_scene()), scene_tensors(Scene(scene.states, valid, scene.sizes, scene.kinds,
                                                                0, 4, 0.5, lanes=scene.lanes))]
    torch.manual_seed(0)
    model = TrafficModel(TrafficModelConfig(hidden=16, latent=4, mixer_layers=1))
    out = evaluate_model(model, items, samples=2)
    for rate in ("collision_rate", "off_road_rate"):
        every, logged_steps = out[rate], out[rate + "_logged_steps"]
        assert logged_steps["logged"] == every["logged"]
        for name in ("prior", "posterior"):
            assert 0.0 <= logged_steps[name] <= every[name]
