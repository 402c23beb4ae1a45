"""`adversary train-traffic`: fit the traffic CVAE on collected windows, report its realism.

Loss per scene: the posterior reconstruction of every agent's known future (mean position
error in units of `position_scale_m`, heading 1 - cos, speed error) plus beta * KL(q || p),
averaged over real agents, plus the realism term when `prior_collision_weight` or
`prior_off_road_weight` is set (`realism_loss`, STRIVE's prior losses): one reparameterised sample
of the PRIOR is decoded per scene and its pairwise disc overlaps and off-road corner distances
(adversary.crash.generate's `collision_penalty` and `off_road_penalty`) are penalised, so that
the prior, not only the posterior, learns that traffic does not drive into itself or off the
road. Pairs of agents whose logged futures overlap (the data's own crashes, kept at its rate)
and agents whose logged future leaves the drivable area are left out of those terms: the prior
is not taught to be cleaner than the data it models (the off-road term also leaves out agents
whose log stops before the horizon: they may leave the mapped area).

Validation holds out whole episodes (the last `val_fraction` of each dataset's shards; for
recorded data whole moments of traffic, `held_out`). Every epoch ends in one
atomic write of RUN/state.pt (`riskmap.infra.training_run`), the commit point that `--resume`
continues from: weights, optimizer, both random generators, the log and the best epoch's sidecar.
RUN/log.jsonl (a line per epoch) and RUN/best (safetensors + sidecar, the best validation ADE)
are derived from it, written after it and again on resume, so a run killed anywhere resumes to
the files of an uninterrupted one. The sidecars name the scenario family and raster extent of the data
(`traffic_model_family`), so that an attack can refuse a model of another family.

Realism metrics (`evaluate_model`), on the validation scenes:
    recon ADE / FDE (m)   posterior mean decoded, against the logged futures of every agent
    prior minADE-K (m)    best of K prior samples per agent
    collision rate        share of scenes in which two agents' boxes overlap at some 2 Hz step,
                          for prior samples and for the logged futures (the data's own rate)
    off-road rate         share of agents with more than 5% of the box off the drivable area at
                          some step (box sampled on a 5 x 3 grid of points), same two columns
    *_logged_steps        both rates with the model's trajectories counted only at the steps
                          where each agent is in the log (agents that leave before the horizon)
"""

from __future__ import annotations

import json
import re
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from adversary.crash.batch import Batch, collate
from adversary.crash.config import TrainTrafficConfig
from adversary.crash.features import FeatureConfig, SceneTensors, scene_tensors
from adversary.crash.generate import _discs, collision_penalty, off_road_penalty
from adversary.crash.traffic_model import TrafficModel, TrafficModelConfig, kl_normal
from rasterize.errors import InputError
from rasterize.frames import box_corners
from rasterize.geometry import boxes_overlap
from riskmap.infra.atomic import write_json
from riskmap.infra.checkpoint import load_weights, read_sidecar
from riskmap.infra.training_run import TrainingRun, jsonl_log

CHECKPOINT_KIND = "traffic_cvae"
# An agent whose logged future puts its box corners this far off the drivable area in all (m,
# summed over the 4 corners and the valid steps) is off-road in the data: the realism term
# leaves it alone. Lane polygons do not cover every corner a turning car cuts by a few cm.
LOGGED_OFF_ROAD_M = 0.5


def _recorded_family(config: dict) -> str | None:
    """The traffic-model family of a `--from-commonroad` dataset's recordings (their site, as
    `adversary.crash.recorded.recording_family` names the attack scenes': us101, lankershim),
    or None for a site it does not know."""
    from adversary.crash.recorded import recording_family

    names = set()
    for name, *_ in config.get("files", ()):
        try:
            names.add(recording_family(name))
        except InputError:
            return None
    return names.pop() if len(names) == 1 else None


def data_family(roots: list[Path]) -> dict:
    """{"family", "extent", "sources"} of datasets collected by `riskmap collect`: the scenario
    family (highway-env's family of the env id; for a `--from-commonroad` dataset the recorded
    site's, e.g. us101, as the attack names recorded scenes, else the recordings' raster family),
    its raster extent (m) and the env ids. Datasets of several families are refused: a traffic
    model is of one family."""
    from rasterize.config import family_of_env
    from riskmap.data.dataset import load_manifest

    families: dict[str, list[str]] = {}
    extents, sources = [], []
    for root in roots:
        config = load_manifest(Path(root)).get("config", {})
        source = config.get("env_id")
        family = config.get("family") or (family_of_env(source) if source and source != "commonroad" else None)
        if source == "commonroad":
            family = _recorded_family(config) or family
        if family is None:
            raise InputError(f"--data {root}: its manifest names no env or family; collect it again "
                             "with `riskmap collect`")
        families.setdefault(family, []).append(str(root))
        extent = config.get("raster", {}).get("extent")
        if extent not in extents:
            extents.append(extent)
        if source not in sources:
            sources.append(source)
    if len(families) > 1:
        listed = "; ".join(f"{f}: {', '.join(r)}" for f, r in sorted(families.items()))
        raise InputError(f"--data mixes scenario families ({listed}); train one traffic model per family")
    return {"family": next(iter(families)), "extent": extents[0] if len(extents) == 1 else extents,
            "sources": sources}


def traffic_model_family(path: Path) -> str | None:
    """The scenario family (highway, intersection, ...) a traffic-model checkpoint `path` (without
    suffix) was trained on; None for a sidecar written before the family was recorded."""
    family = read_sidecar(Path(path), kind=CHECKPOINT_KIND).get("family")
    return None if family is None else str(family)


def _natural(name: str) -> list:
    """Sort key that puts `USA_US101-2` before `USA_US101-10`."""
    return [(0, int(p), "") if p.isdigit() else (1, 0, p) for p in re.split(r"(\d+)", name)]


def held_out(data, val_fraction: float) -> set[int]:
    """The episodes (shards) of dataset `data` that validate: the last `val_fraction` of its
    episodes. Recorded data (`--from-commonroad`) is split by group instead (its episodes are
    demonstrators of shared moments of traffic, named by `group_of`), so that no recorded vehicle
    is on both sides: walking the groups from the last in natural order, a group validates when
    the validation windows stay within `val_fraction` of all (else the smallest group alone).
    Recorded data of a single group is split by episodes like simulated data."""
    episodes = sorted({data.episode_of(i) for i in range(len(data))})
    if val_fraction <= 0:
        return set()
    groups = {data.episode_of(i): data.group_of(i) for i in range(len(data))}
    if all(g is not None for g in groups.values()) and len(set(groups.values())) > 1:
        windows: dict[str, int] = {}
        for i in range(len(data)):
            windows[groups[data.episode_of(i)]] = windows.get(groups[data.episode_of(i)], 0) + 1
        chosen, count = [], 0
        for name in sorted(windows, key=_natural, reverse=True)[:-1]:     # one group always trains
            if count + windows[name] <= val_fraction * len(data):
                chosen.append(name)
                count += windows[name]
        if not chosen:
            chosen = [min(sorted(windows, key=_natural), key=windows.get)]
        return {ep for ep, g in groups.items() if g in chosen}
    kept = round(len(episodes) * (1.0 - val_fraction))     # episodes that train
    return set(episodes[kept:])


def load_windows(roots: list[Path], features: FeatureConfig, val_fraction: float,
                 max_per_episode: int = 0) -> tuple[list[SceneTensors], list[SceneTensors]]:
    """(train, validation) scene tensors of datasets collected by `riskmap collect` (validation:
    `held_out`)."""
    from riskmap.data.dataset import DemoDataset

    train, val = [], []
    for root in roots:
        data = DemoDataset(root)
        validating = held_out(data, val_fraction)
        taken: dict[int, int] = {}
        for i in range(len(data)):
            ep = data.episode_of(i)
            if max_per_episode and taken.get(ep, 0) >= max_per_episode:
                continue
            taken[ep] = taken.get(ep, 0) + 1
            try:
                item = scene_tensors(data.scene(i), features)
            except InputError:
                continue          # a window without map or history: nothing to learn from
            (val if ep in validating else train).append(item)
    if not train:
        raise InputError(f"--data {', '.join(map(str, roots))} gave no usable training windows")
    return train, val


def reconstruction_loss(model: TrafficModel, batch: Batch, traj: torch.Tensor) -> torch.Tensor:
    """Per-agent loss [B, N] of decoded trajectories [B, N, F, 4] against batch.future."""
    s = model.config
    valid = batch.future_valid.float()
    pos = (traj[..., :2] - batch.future[..., :2]).norm(dim=-1) / s.position_scale_m
    heading = 1.0 - (torch.cos(traj[..., 2]) * batch.future[..., 2] + torch.sin(traj[..., 2]) * batch.future[..., 3])
    speed = (traj[..., 3] - batch.future[..., 4]).abs() / s.speed_scale_mps
    per_step = pos + heading + 0.5 * speed
    return (per_step * valid).sum(-1) / valid.sum(-1).clamp(min=1.0)


def _logged_states(batch: Batch) -> torch.Tensor:
    """The logged futures [B, N, F, 4] (x, y, heading, speed) of batch.future."""
    f = batch.future
    return torch.stack([f[..., 0], f[..., 1], torch.atan2(f[..., 3], f[..., 2]), f[..., 4]], -1)


@torch.no_grad()
def logged_overlaps(batch: Batch) -> torch.Tensor:
    """[B, N, N] bool: the discs of the two agents' logged futures overlap at a step where both
    are known (the data's own crashes and near-contacts, as the realism term measures them)."""
    centres, radius = _discs(_logged_states(batch), batch.sizes)            # [B, N, F, 3, 2]
    a, c = centres[:, :, None, :, :, None], centres[:, None, :, :, None, :]
    dist = (a - c).norm(dim=-1)                                              # [B, N, N, F, 3, 3]
    reach = (radius[:, :, None] + radius[:, None, :]).squeeze(-1)[..., None, None]   # [B, N, N, 1, 1, 1]
    overlap = ((reach - dist) > 0).flatten(-2).any(-1)                       # [B, N, N, F]
    both = batch.future_valid[:, :, None] & batch.future_valid[:, None, :]
    n = both.shape[1]
    return (overlap & both).any(-1) & ~torch.eye(n, dtype=torch.bool)[None]


@torch.no_grad()
def logged_off_road(batch: Batch) -> torch.Tensor:
    """[B, N] bool: the agent's logged future is off the drivable area (`LOGGED_OFF_ROAD_M`)."""
    logged = _logged_states(batch)
    # Unknown steps take the last known state (for an agent never known: its present, t0).
    now = batch.past[:, :, -1]
    last = torch.stack([now[..., 0], now[..., 1], torch.atan2(now[..., 3], now[..., 2]), now[..., 4]], -1)
    steps = []
    for t in range(logged.shape[2]):
        last = torch.where(batch.future_valid[:, :, t, None], logged[:, :, t], last)
        steps.append(last)
    logged = torch.stack(steps, 2)
    b, n = batch.agent_mask.shape
    out = torch.zeros(b, n, dtype=torch.bool)
    for k in range(n):          # off_road_penalty averages over the masked agents: one at a time
        one = torch.zeros(b, n, dtype=torch.bool)
        one[:, k] = True
        out[:, k] = off_road_penalty(batch, logged, one) > LOGGED_OFF_ROAD_M
    return out


def realism_loss(model: TrafficModel, batch: Batch, enc, collision_weight: float, off_road_weight: float
                 ) -> tuple[torch.Tensor, dict]:
    """The realism term (module docstring) of one reparameterised prior sample per scene: (loss,
    parts). Collision: disc overlap (m) summed over the steps and the pairs of real agents that do
    not overlap in the log; off-road: corner distances (m) summed over corners and steps, for the
    real agents logged to the horizon that stay on the road in the log; both per real agent of
    the batch. The gradient reaches every weight (encoder, prior, decoder), as in STRIVE."""
    eps = torch.randn_like(enc.prior_mu)
    traj = model.decode(batch, enc, enc.prior_mu + eps * (0.5 * enc.prior_logvar).exp())
    agents = batch.agent_mask
    count = agents.float().sum().clamp(min=1.0)
    n = agents.shape[1]
    pair = agents[:, :, None] & agents[:, None, :] & ~torch.eye(n, dtype=torch.bool)[None]
    pair = pair & ~logged_overlaps(batch)
    collision = collision_penalty(traj, batch.sizes, pair).sum() / count
    # Only agents logged to the end of the horizon: one whose log stops may have left the mapped
    # area (recorded traffic, highway-env's exits), where off the lanes is not off the road.
    on_road = agents & batch.future_valid.all(-1) & ~logged_off_road(batch)
    # off_road_penalty is the mean over the masked agents of a scene: back to their sum
    off_road = (off_road_penalty(batch, traj, on_road) * on_road.float().sum(-1)).sum() / count
    loss = collision_weight * collision + off_road_weight * off_road
    return loss, {"prior_collision": float(collision.detach()), "prior_off_road": float(off_road.detach())}


def training_loss(model: TrafficModel, batch: Batch, kl_weight: float, free_bits: float = 0.0,
                  collision_weight: float = 0.0, off_road_weight: float = 0.0
                  ) -> tuple[torch.Tensor, dict]:
    """The loss of the module docstring and its parts; the realism term only when one of its
    weights is set (so that without it nothing more is drawn from torch's generator)."""
    enc = model.encode(batch)
    mu, logvar = model.posterior_of(batch, enc)
    z = mu + torch.randn_like(mu) * (0.5 * logvar).exp()
    traj = model.decode(batch, enc, z)
    agents = (batch.agent_mask & batch.future_valid.any(-1)).float()
    recon = (reconstruction_loss(model, batch, traj) * agents).sum() / agents.sum().clamp(min=1.0)
    kl_agent = kl_normal(mu, logvar, enc.prior_mu, enc.prior_logvar)
    kl = (kl_agent * agents).sum() / agents.sum().clamp(min=1.0)
    penalised = (torch.relu(kl_agent - free_bits) * agents).sum() / agents.sum().clamp(min=1.0)
    loss, parts = recon + kl_weight * penalised, {"recon": float(recon.detach()), "kl": float(kl.detach())}
    if collision_weight > 0 or off_road_weight > 0:
        realism, more = realism_loss(model, batch, enc, collision_weight, off_road_weight)
        loss, parts = loss + realism, {**parts, **more}
    return loss, parts


def _batches(items: list, size: int, rng: np.random.Generator | None):
    order = np.arange(len(items)) if rng is None else rng.permutation(len(items))
    for start in range(0, len(items), size):
        yield collate([items[i] for i in order[start:start + size]])


def _box_points(traj: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Points [N, F, 15, 2] on a 5 x 3 grid over every box of trajectories [N, F, 4]."""
    u = np.linspace(-0.5, 0.5, 5)
    v = np.linspace(-0.5, 0.5, 3)
    uu, vv = np.meshgrid(u, v)
    local = np.stack([uu.ravel(), vv.ravel()], -1)                      # [15, 2]
    length, width = sizes[:, None, None, 0], sizes[:, None, None, 1]
    c, s = np.cos(traj[..., 2])[..., None], np.sin(traj[..., 2])[..., None]
    lx, ly = local[None, None, :, 0] * length, local[None, None, :, 1] * width
    return np.stack([traj[..., None, 0] + c * lx - s * ly, traj[..., None, 1] + s * lx + c * ly], -1)


def scene_collides(traj: np.ndarray, sizes: np.ndarray, valid: np.ndarray) -> bool:
    """Whether two agents' boxes overlap at some step; traj [N, F, 4], valid [N, F]."""
    f = valid.shape[1]
    for t in range(f):
        live = np.flatnonzero(valid[:, t])
        for a_i, a in enumerate(live):
            for b in live[a_i + 1:]:
                if np.linalg.norm(traj[a, t, :2] - traj[b, t, :2]) > 0.5 * (sizes[a, 0] + sizes[b, 0]) + 1.0:
                    continue
                box_a = box_corners(traj[a, t, :2], [np.cos(traj[a, t, 2]), np.sin(traj[a, t, 2])], *sizes[a])
                box_b = box_corners(traj[b, t, :2], [np.cos(traj[b, t, 2]), np.sin(traj[b, t, 2])], *sizes[b])
                if boxes_overlap(box_a, box_b):
                    return True
    return False


def off_road_agents(item: SceneTensors, traj: np.ndarray, valid: np.ndarray,
                    threshold: float = 0.05) -> np.ndarray:
    """[N] bool: more than `threshold` of the box off the drivable area at some valid step."""
    points = _box_points(traj, item.sizes)
    off = item.off_road.sample(points) > 0.0                             # [N, F, 15]
    return ((off.mean(-1) > threshold) & valid).any(-1)


def _logged_traj(item: SceneTensors) -> np.ndarray:
    f = item.future
    return np.stack([f[..., 0], f[..., 1], np.arctan2(f[..., 3], f[..., 2]), f[..., 4]], -1)


@torch.no_grad()
def evaluate_model(model: TrafficModel, items: list[SceneTensors], samples: int = 5, seed: int = 0,
                   batch_size: int = 64) -> dict:
    model.eval()
    gen = torch.Generator().manual_seed(seed)
    ade, fde, min_ade = [], [], []
    coll = {"prior": 0, "posterior": 0, "logged": 0}
    off = {"prior": [0, 0], "posterior": [0, 0], "logged": [0, 0]}
    coll_known = {"prior": 0, "posterior": 0}
    off_known = {"prior": 0, "posterior": 0}
    for start in range(0, len(items), batch_size):
        chunk = items[start:start + batch_size]
        batch = collate(chunk)
        enc = model.encode(batch)
        mu, _ = model.posterior_of(batch, enc)
        recon = model.decode(batch, enc, mu).numpy()
        prior = []
        for _ in range(samples):
            eps = torch.randn(enc.prior_mu.shape, generator=gen)
            prior.append(model.decode(batch, enc, enc.prior_mu + eps * (0.5 * enc.prior_logvar).exp()).numpy())
        for i, item in enumerate(chunk):
            n = item.num_agents
            valid = item.future_valid
            err = np.linalg.norm(recon[i, :n, :, :2] - item.future[..., :2], axis=-1)
            has = valid.any(-1)
            ade.extend((err * valid).sum(-1)[has] / valid.sum(-1)[has])
            full = valid[:, -1]
            fde.extend(err[full, -1])
            sample_err = np.stack([np.linalg.norm(p[i, :n, :, :2] - item.future[..., :2], axis=-1)
                                   for p in prior])                    # [K, N, F]
            min_ade.extend(((sample_err * valid).sum(-1) / valid.sum(-1).clip(min=1)).min(0)[has])
            every = np.ones_like(valid)
            coll_before = dict(coll)
            for name, traj, mask in (("prior", prior[0][i, :n], every), ("posterior", recon[i, :n], every),
                                     ("logged", _logged_traj(item), valid)):
                coll[name] += scene_collides(traj, item.sizes, mask)
                agents = off_road_agents(item, traj, mask)
                off[name][0] += int(agents.sum())
                off[name][1] += n
                if name != "logged" and not valid.all():     # else the same as over every step
                    coll_known[name] += scene_collides(traj, item.sizes, valid)
                    off_known[name] += int(off_road_agents(item, traj, valid).sum())
                elif name != "logged":
                    coll_known[name] += coll[name] - coll_before[name]
                    off_known[name] += int(agents.sum())
    scenes = len(items)
    return {
        "scenes": scenes, "agents": off["logged"][1],
        "recon_ade_m": float(np.mean(ade)), "recon_fde_m": float(np.mean(fde)),
        f"prior_min_ade_{samples}_m": float(np.mean(min_ade)),
        "collision_rate": {k: v / scenes for k, v in coll.items()},
        "off_road_rate": {k: v[0] / max(v[1], 1) for k, v in off.items()},
        # The same two measures of the model's trajectories at the logged steps only (each agent
        # while it is in the log): like for like with the logged column where agents leave
        # before the horizon (recorded traffic, highway-env's exits).
        "collision_rate_logged_steps": {**{k: v / scenes for k, v in coll_known.items()},
                                        "logged": coll["logged"] / scenes},
        "off_road_rate_logged_steps": {**{k: v / max(off["logged"][1], 1) for k, v in off_known.items()},
                                       "logged": off["logged"][0] / max(off["logged"][1], 1)},
    }


def load_traffic_model(path: Path) -> tuple[TrafficModel, FeatureConfig, dict]:
    data = read_sidecar(path, kind=CHECKPOINT_KIND)
    features = FeatureConfig(**data["features"])
    model = load_weights(TrafficModel(TrafficModelConfig(**data["model"]), features.lane_chunks,
                                      features.chunk_points), path, "train it again with `adversary train-traffic`")
    return model, features, data


def train_traffic(data: list[Path], out: Path, config: TrainTrafficConfig = TrainTrafficConfig(),
                  model_config: TrafficModelConfig | None = None,
                  features: FeatureConfig | None = None, resume: bool = False,
                  progress: bool = True) -> dict:
    model_config = model_config or TrafficModelConfig()
    features = features or FeatureConfig()
    out = Path(out)
    # Best by validation reconstruction ADE. No settings are compared on resume.
    run = TrainingRun(out, resume, metric="val_recon_ade_m").refuse("a run", markers=(None,))
    started = time.perf_counter()
    # The data is read (and bad data refused) before --out exists.
    family = data_family(data)
    train, val = load_windows(data, features, config.val_fraction, config.max_windows_per_episode)
    run.lock()   # one writer per run directory (creates it)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    model = TrafficModel(model_config, features.lane_chunks, features.chunk_points)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    meta = {"config": asdict(config), "model": model_config.to_dict(), "features": asdict(features),
            "data": [str(d) for d in data], **family, "train_scenes": len(train), "val_scenes": len(val)}
    best_sidecar = None       # the best epoch's: its full validation metrics are in no log row
    run.publishes(log=jsonl_log(), sidecar=lambda epoch: best_sidecar, kind=CHECKPOINT_KIND)
    state = run.resume_from(model, optimizer)
    if state is not None and "numpy_rng" in state:
        best_sidecar = state["best_sidecar"]
        rng.bit_generator.state = state["numpy_rng"]
        # The files derived from the commit point, as it left them: a kill may have cut them
        # off, or written those of an epoch that did not commit.
        run.republish(model)
    elif state is not None:   # a state.pt of an older version: its log lines, a new draw of the data order
        log = out / "log.jsonl"
        lines = log.read_text().splitlines() if log.exists() else []
        run.log = [r for r in map(json.loads, filter(str.strip, lines)) if r["epoch"] < run.first_epoch]
        rng = np.random.default_rng([config.seed, run.first_epoch])
    write_json(out / "run.json", meta)
    for epoch in range(run.first_epoch, config.epochs):
        model.train()
        losses = []
        for batch in _batches(train, config.batch_size, rng):
            loss, parts = training_loss(model, batch, config.kl_weight, config.free_bits,
                                        config.prior_collision_weight, config.prior_off_road_weight)
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 5.0)
            optimizer.step()
            losses.append(parts)
        metrics = evaluate_model(model, val or train[:64], samples=1, seed=epoch)
        record = {"epoch": epoch, "train_recon": float(np.mean([p["recon"] for p in losses])),
                  "train_kl": float(np.mean([p["kl"] for p in losses])),
                  **{f"train_{k}": float(np.mean([p[k] for p in losses])) for k in ("prior_collision", "prior_off_road")
                     if k in losses[0]},
                  "val_recon_ade_m": metrics["recon_ade_m"], "val_recon_fde_m": metrics["recon_fde_m"],
                  "val_prior_collision_rate": metrics["collision_rate"]["prior"],
                  "val_prior_off_road_rate": metrics["off_road_rate"]["prior"],
                  "elapsed_s": round(time.perf_counter() - started, 1)}
        if progress:
            print(json.dumps(record), flush=True)
        if run.better(record):
            best_sidecar = {**meta, "epoch": epoch, "val": metrics}
        # The commit point of the epoch: one file with all that resume needs (the log, the data
        # order's generator and the best epoch's sidecar too); log.jsonl and best.* are derived
        # from it, after it.
        run.commit(model, optimizer, record,
                   extra={"numpy_rng": rng.bit_generator.state, "best_sidecar": best_sidecar})
    model, _, _ = load_traffic_model(out / "best")
    final = evaluate_model(model, val or train[:64], samples=5, seed=config.seed)
    summary = {**meta, "best_val_recon_ade_m": run.best_value, "val": final,
               "elapsed_s": round(time.perf_counter() - started, 1)}
    write_json(out / "summary.json", summary)
    return summary
