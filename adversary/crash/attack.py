"""One CRASH attack: select an adversary in a recorded scene, generate, judge in the simulator.

    1. the scene's window -> traffic-model tensors; latents start at the posterior mean of the
       logged futures (`z_init`)
    2. the ego's future: the logged one for `replay`; otherwise the planner under test driven
       in closed loop against the logged traffic (`judge.rollout`)
    3. p from the selector (`SELECTORS`), the adversary = argmax p
    4. `generate`: Adam on the non-ego latents; a closed-loop planner is re-run on the current
       trajectories every k = `replan_every` iterations and the ego's row follows it
    5. the final trajectories are spliced into the log and the planner drives once more; the
       judge measures that rollout (STRIVE's metrics, `adversary.crash.judge.judge`)

The record of one attack is JSON-ready: the scene, selector, p over the window rows, the
adversary, the generated tracks, the metrics, and where the time went.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from adversary.crash.batch import collate
from adversary.crash.features import SceneTensors, _to_frame, scene_tensors
from adversary.crash.generate import GenerationConfig, generate, logged_ego_future
from adversary.crash.selection import (
    SELECTORS,
    candidates,
    distance_weights,
    nearest_weights,
    random_weights,
)
from adversary.crash.traffic_model import states_of
from rasterize.errors import InputError


@dataclass(frozen=True)
class AttackConfig:
    selector: str = "crash"
    replan_every: int = 20              # k (closed-loop planners)
    iterations_replay: int = 300        # CRASH / STRIVE
    iterations_closed_loop: int = 200
    lr: float = 0.05
    stop_on_collision: bool = True

    def __post_init__(self) -> None:
        if self.selector not in SELECTORS:
            raise InputError(f"selector {self.selector!r} is unknown; use one of {', '.join(SELECTORS)}")
        if self.replan_every < 1:
            raise InputError(f"replan_every (k) must be >= 1, got {self.replan_every}")

    def generation(self, closed_loop: bool) -> GenerationConfig:
        return GenerationConfig(iterations=self.iterations_closed_loop if closed_loop else self.iterations_replay,
                                lr=self.lr, replan_every=self.replan_every,
                                stop_on_collision=self.stop_on_collision)


@dataclass(frozen=True)
class Models:
    """The trained parts an attack needs (loaded once per process)."""

    traffic: object                     # TrafficModel
    features: object                    # FeatureConfig
    selector_mam: object | None = None  # SelectionModule trained with MAM candidates
    selector_no_mam: object | None = None


def load_models(traffic_path: Path, selector_dir: Path | None) -> Models:
    from adversary.crash.train_selector import load_selector
    from adversary.crash.train_traffic import load_traffic_model

    traffic, features, _ = load_traffic_model(traffic_path)
    mam = no_mam = None
    if selector_dir is not None:
        mam, _ = load_selector(Path(selector_dir) / "selector_mam")
        no_mam, _ = load_selector(Path(selector_dir) / "selector_no_mam")
    return Models(traffic, features, mam, no_mam)


def world_tracks(item: SceneTensors, traj: np.ndarray) -> np.ndarray:
    """Scene-frame trajectories [N, F, 4] of all N agents as world states [N, F, 6] with yaw rates."""
    world = item.world_states(states_of(torch.from_numpy(traj)).numpy())
    heading = np.concatenate([np.arctan2(item.past[:, -1:, 3], item.past[:, -1:, 2]) + item.heading,
                              np.arctan2(world[..., 3], world[..., 2])], axis=1)
    world[..., 5] = np.diff(np.unwrap(heading, axis=1), axis=1) / 0.5
    return world


def scene_frame_ego(item: SceneTensors, ego_world: np.ndarray) -> torch.Tensor:
    """World ego states [F, 6] as a scene-frame future [1, F, 4] (x, y, heading, speed)."""
    framed = _to_frame(ego_world, item.origin, item.heading)
    out = np.stack([framed[:, 0], framed[:, 1], np.arctan2(framed[:, 3], framed[:, 2]), framed[:, 4]], -1)
    return torch.from_numpy(out[None].astype(np.float32))


def selection(config: AttackConfig, models: Models, batch, enc, z_init, ego_future, rng) -> torch.Tensor:
    mam = config.selector in ("crash", "distance+mam")
    mask = candidates(batch, mam=mam)
    if config.selector in ("crash", "crash-no-mam"):
        selector = models.selector_mam if mam else models.selector_no_mam
        if selector is None:
            raise InputError(f"selector {config.selector} needs a trained selector; pass --selector-model "
                             "DIR (from `adversary train-selector`)")
        with torch.no_grad():
            return selector(enc.context, mask)
    if config.selector in ("distance", "distance+mam"):
        from adversary.crash.generate import _decode_with_ego

        with torch.no_grad():
            traj = _decode_with_ego(models.traffic, batch, enc, z_init, ego_future)
        return distance_weights(traj, ego_future, batch, mask)
    if config.selector == "nearest":
        return nearest_weights(batch, mask)
    return random_weights(mask, rng)


def attack_record(record, models: Models, planner, planner_spec: str, config: AttackConfig,
                  seed: int, panel: Path | None = None) -> dict:
    """Run one attack on `record` (an `adversary.crash.scenes.SceneRecord`); see the module docstring."""
    from adversary.crash.judge import ego_future_2hz, judge, rollout

    started = time.perf_counter()
    timing = {"rollout_s": 0.0, "rollouts": 0}
    item = scene_tensors(record.window, models.features)
    batch = collate([item])
    model = models.traffic
    closed_loop = planner_spec != "replay"
    rows = item.rows
    n = item.num_agents

    def drive(traj: np.ndarray | None):
        t = time.perf_counter()
        tracks = (np.zeros((0, 12, 6)) if traj is None else world_tracks(item, traj[:n])[1:])
        result = rollout(record, tracks, rows[1:] if traj is not None else [], planner, planner_spec)
        timing["rollout_s"] += time.perf_counter() - t
        timing["rollouts"] += 1
        return tracks, result

    with torch.no_grad():
        enc = model.encode(batch)
        z_init, _ = model.posterior_of(batch, enc)
    if closed_loop:
        _, first = drive(None)
        ego_future = scene_frame_ego(item, ego_future_2hz(first))
    else:
        ego_future = logged_ego_future(batch)
    rng = np.random.default_rng(seed)
    p = selection(config, models, batch, enc, z_init, ego_future, rng)
    base = {"scene": asdict(record.scene), "planner": planner_spec, "selector": config.selector,
            "config": asdict(config), "seed": seed, "agents": n,
            "candidates": int((p[0] > 0).sum()) if p.sum() > 0 else 0,
            "p": [round(float(v), 5) for v in p[0, :n]]}
    if p.sum() <= 0:
        return {**base, "status": "no_candidate", "collision": False,
                "seconds": time.perf_counter() - started}

    def replan(traj: torch.Tensor) -> torch.Tensor:
        _, result = drive(traj[0].numpy())
        return scene_frame_ego(item, ego_future_2hz(result))

    gen = generate(model, batch, p, ego_future, config.generation(closed_loop),
                   replan=replan if closed_loop else None, z_init=z_init)
    adversary = int(gen.adversary[0])
    traj = gen.traj[0].numpy()
    tracks, final = drive(traj)
    metrics = judge(record, tracks, rows[1:], int(rows[adversary]), planner, planner_spec, result=final)
    if panel is not None:
        from adversary.crash.panel import save_attack_panel

        save_attack_panel(record, tracks, rows[1:], int(rows[adversary]), final, metrics, panel,
                          f"{record.scene.env_id} seed {record.scene.scene_seed} episode "
                          f"{record.scene.episode} | {planner_spec} | {config.selector}")
    return {**base, "status": "ok", "adversary_row": int(rows[adversary]),
            "adversary_log_id": int(record.agent_ids[rows[adversary]]),
            "collision": bool(metrics["collision"]), "metrics": metrics,
            "generation": {"iterations": gen.iterations, "replans": gen.replans,
                           "seconds": round(gen.seconds, 3), "losses": gen.losses},
            "tracks": np.round(tracks, 3).tolist(),
            "timing": {**timing, "rollout_s": round(timing["rollout_s"], 3)},
            "seconds": time.perf_counter() - started}
