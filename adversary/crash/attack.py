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
adversary, the generated tracks, the metrics, where the time went, and the plans that failed the
planner contract's checks over every drive of the scene (`implausible_plans`, with the first
one's problems; `riskmap.sim.loop.plan_checks`: driven as made, counted).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from adversary.crash.batch import collate
from adversary.crash.features import SceneTensors, _to_frame, scene_tensors
from adversary.crash.generate import TIME_WEIGHTINGS, GenerationConfig, generate, logged_ego_future
from adversary.crash.scenes import CONTROL_HZ
from adversary.crash.selection import (
    SELECTORS,
    candidates,
    distance_weights,
    nearest_weights,
    random_weights,
)
from adversary.crash.traffic_model import states_of
from rasterize.errors import InputError
from rasterize.timebase import REPLAN_HZ
from riskmap.sim.loop.plan_checks import ImplausiblePlans
from riskmap.sim.loop.rollout import check_replan_hz

# The validity terms' weights: the adversary-other overlap weighs as STRIVE's non-adversary
# collisions (20 per metre of disc overlap); the kinematic excess 5 per squared unit, so that
# 1 m/s² over a limit for one 0.5 s step costs about what 2 m of mean distance to the ego does.
VALIDITY_COLLISION_WEIGHT = 20.0
VALIDITY_KINEMATIC_WEIGHT = 5.0
# k (`AttackConfig.replan_every`) per shipped planner (`riskmap.planner.shipped`): a risk-aware
# planner rollout costs ~8x an IDM one on a CPU, so it is re-run every 50 iterations.
REPLAN_EVERY = {"replay": 20, "idm": 20, "riskmap": 50}


@dataclass(frozen=True)
class AttackConfig:
    selector: str = "crash"
    replan_every: int = 20              # k (closed-loop planners)
    replan_hz: int = REPLAN_HZ          # how often the ego under test replans in every drive (Hz,
                                        # a divisor of the 10 Hz control rate; 2 is the planner
                                        # paper's step and every drive's default)
    iterations_replay: int = 300        # CRASH / STRIVE
    iterations_closed_loop: int = 200
    lr: float = 0.15                    # Adam's step on the latents: 0.15 beat 0.05 on every family
                                        # measured (experiments/README, "CRASH at strength")
    stop_on_collision: bool = True
    time_weighting: str = "sum"         # GenerationConfig.time_weighting
    validity_terms: bool = True         # the adversary-other collision and kinematic terms
                                        # (adversary.crash.generate); False: the paper's eq. 8

    def __post_init__(self) -> None:
        if self.selector not in SELECTORS:
            raise InputError(f"selector {self.selector!r} is unknown; use one of {', '.join(SELECTORS)}")
        if self.replan_every < 1:
            raise InputError(f"replan_every (k) must be >= 1, got {self.replan_every}")
        check_replan_hz(self.replan_hz, CONTROL_HZ)
        if not (self.lr > 0 and self.lr < float("inf")):
            raise InputError(f"--lr {self.lr}: must be a positive number")
        if self.time_weighting not in TIME_WEIGHTINGS:
            raise InputError(f"--time-weighting {self.time_weighting!r} is unknown; use one of "
                             f"{', '.join(TIME_WEIGHTINGS)}")

    def generation(self, closed_loop: bool) -> GenerationConfig:
        validity = {"adversary_collision_weight": VALIDITY_COLLISION_WEIGHT,
                    "kinematic_weight": VALIDITY_KINEMATIC_WEIGHT} if self.validity_terms else {}
        return GenerationConfig(iterations=self.iterations_closed_loop if closed_loop else self.iterations_replay,
                                lr=self.lr, replan_every=self.replan_every,
                                stop_on_collision=self.stop_on_collision, time_weighting=self.time_weighting,
                                **validity)


def replan_hz_of(attack: dict) -> int:
    """The replanning rate an attack record's drives used (records from before `replan_hz`
    existed: 2 Hz), so that driving it again reproduces it."""
    return int(attack.get("config", {}).get("replan_hz", AttackConfig.replan_hz))


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


def _ego_in_scene_frame(item: SceneTensors, track_world: np.ndarray) -> np.ndarray:
    """World ego states [T, 6] as scene-frame (x, y, cos, sin, speed) [T, 5]."""
    return _to_frame(track_world, item.origin, item.heading).astype(np.float32)


def attack_records(records: list, models: Models, planner, planner_spec: str, config: AttackConfig,
                   seeds: list[int], panels: list[Path | None] | None = None,
                   keep_scenes: bool = False) -> list[dict]:
    """Attack every record (`adversary.crash.scenes.SceneRecord`) in one batch; one JSON-ready
    dict per record (module docstring). Scenes are independent: batching only saves time.
    `keep_scenes`: an attacked record's dict also holds the final drive's last step as a Scene
    (`final_scene`, not JSON) and the adversary's world position then (`adversary_xy`)."""
    from adversary.crash.judge import collided_with, ego_track_2hz, judge, rollout

    started = time.perf_counter()
    b = len(records)
    timing = [{"rollout_s": 0.0, "rollouts": 0} for _ in range(b)]
    implausible = [ImplausiblePlans() for _ in range(b)]       # over every drive of a scene
    items = [scene_tensors(r.window, models.features) for r in records]
    model = models.traffic
    closed_loop = planner_spec != "replay"

    def drive(i: int, traj: np.ndarray | None, keep_scene: bool = False):
        t = time.perf_counter()
        n = items[i].num_agents
        tracks = np.zeros((0, 12, 6)) if traj is None else world_tracks(items[i], traj[:n])[1:]
        result = rollout(records[i], tracks, items[i].rows[1:] if traj is not None else [], planner,
                         planner_spec, replan_hz=config.replan_hz, keep_scene=keep_scene)
        timing[i]["rollout_s"] += time.perf_counter() - t
        timing[i]["rollouts"] += 1
        implausible[i].add_record(result.drive)
        return tracks, result

    if closed_loop:
        # The planner drives from t = 0, so by t0 its ego is not where the human was: the model's
        # ego node takes the planner's own history, and its future is what the planner does
        # against the logged traffic.
        for i in range(b):
            _, first = drive(i, None)
            track = _ego_in_scene_frame(items[i], ego_track_2hz(first))
            items[i] = replace(items[i], past=np.concatenate([track[None, :5], items[i].past[1:]]),
                               future=np.concatenate([track[None, 5:], items[i].future[1:]]),
                               past_valid=np.concatenate([np.ones((1, 5), bool), items[i].past_valid[1:]]),
                               future_valid=np.concatenate([np.ones((1, 12), bool), items[i].future_valid[1:]]))
    batch = collate(items)
    ego_future = logged_ego_future(batch)
    with torch.no_grad():
        enc = model.encode(batch)
        z_init, _ = model.posterior_of(batch, enc)
    p = torch.zeros(b, batch.past.shape[1])
    for i in range(b):
        # Selection scene by scene: the random draw depends only on the scene's own seed.
        single = collate([items[i]])
        with torch.no_grad():
            enc_i = model.encode(single)
            z_i, _ = model.posterior_of(single, enc_i)
        p[i, :items[i].num_agents] = selection(config, models, single, enc_i, z_i, logged_ego_future(single),
                                               np.random.default_rng(seeds[i]))[0]

    adversary_rows = p.argmax(-1)

    def replan(traj: torch.Tensor, scenes: list[int]) -> tuple[torch.Tensor, list[bool]]:
        futures, hits = [], []
        for i in scenes:
            _, result = drive(i, traj[i].numpy())
            futures.append(torch.from_numpy(_future_of(_ego_in_scene_frame(items[i], ego_track_2hz(result)[5:]))))
            hits.append(collided_with(result, records[i], int(items[i].rows[int(adversary_rows[i])])))
        return torch.stack(futures), hits

    gen = generate(model, batch, p, ego_future, config.generation(closed_loop),
                   replan=replan if closed_loop else None, z_init=z_init)
    shared_s = (time.perf_counter() - started - sum(t["rollout_s"] for t in timing)) / b
    out = []
    for i, (record, item) in enumerate(zip(records, items)):
        n = item.num_agents
        base = {"scene": asdict(record.scene), "planner": planner_spec, "selector": config.selector,
                "config": asdict(config), "seed": seeds[i], "agents": n,
                "candidates": int((p[i] > 0).sum()), "p": [round(float(v), 5) for v in p[i, :n]]}
        adversary = int(gen.adversary[i])
        if adversary < 0:
            # MAM drops the vehicles that stood still, DS those behind the ego
            out.append({**base, "status": "no_candidate", "collision": False,
                        "why": f"{n - 1} other vehicles in the window, none a candidate of the "
                               f"{config.selector} selector",
                        "seconds": shared_s + timing[i]["rollout_s"], "timing": timing[i],
                        **implausible[i].fields()})
            continue
        tracks, final = drive(i, gen.traj[i].numpy(), keep_scene=keep_scenes)
        adv_row = int(item.rows[adversary])
        metrics = judge(record, tracks, item.rows[1:], adv_row, planner, planner_spec, result=final)
        panel = panels[i] if panels else None
        if panel is not None:
            from adversary.crash.panel import save_attack_panel
            from riskmap.registry import display_name

            save_attack_panel(record, tracks, item.rows[1:], adv_row, final, metrics, panel,
                              f"{record.scene.where} | {display_name(planner_spec)} | {config.selector}")
        out.append({**base, "status": "ok", "adversary_row": adv_row,
                    "adversary_log_id": int(record.agent_ids[adv_row]),
                    "collision": bool(metrics["collision"]), "metrics": metrics,
                    "generation": {"iterations": gen.iterations[i], "replans": gen.replans[i],
                                   "batch_seconds": round(gen.seconds, 3), "batch_size": b,
                                   "losses": gen.losses if i == 0 else None},
                    "tracks": np.round(tracks, 3).tolist(),
                    # the ego's 10 Hz drive from t = 0 (training windows: `adversary.harden`)
                    "ego_states": np.round(final.states[final.ego][final.valid[final.ego]], 6).tolist(),
                    "timing": {**timing[i], "rollout_s": round(timing[i]["rollout_s"], 3)},
                    # this scene's rollouts plus an equal share of the batch's optimisation
                    "seconds": shared_s + timing[i]["rollout_s"], **implausible[i].fields()})
        if keep_scenes:
            out[-1]["final_scene"] = final.final_scene
            adv = final.recorder_id(int(record.agent_ids[adv_row]))
            alive = adv >= 0 and final.valid[adv].any()
            last = int(np.flatnonzero(final.valid[adv])[-1]) if alive else -1
            out[-1]["adversary_xy"] = (final.states[adv, last, :2].copy()
                                       if alive and last == final.valid.shape[1] - 1 else None)
    return out


def _future_of(framed: np.ndarray) -> np.ndarray:
    """Scene-frame (x, y, cos, sin, speed) [F, 5] as (x, y, heading, speed) [F, 4]."""
    return np.stack([framed[:, 0], framed[:, 1], np.arctan2(framed[:, 3], framed[:, 2]), framed[:, 4]],
                    -1).astype(np.float32)
