"""Guard accident windows from CRASH attacks: positives from the adversary's collisions.

Every attack record with generated tracks (OUT/attacks/<scene>.json of `adversary attack`) is
driven again: the attacked planner against the stored trajectories (`judge.rollout`, the same
closed loop the attack was judged in; the ego passes through boxes, so the episode runs the
whole horizon), and `judge.judge` finds the collisions (box IoU > 0.02, from t0 on). A record
with a collision is cut at the ego's first collision step (with anyone: windows after a
collision would be labelled as normal driving) and turned into guard windows with
`riskmap.guard.dataset.extract_windows` (crashed at the cut: windows of the partner end 0.1 s ... 3 s before
it, against the neighbour with the smallest d_s there, which must be the adversary when the
first collision is the adversary's); a record without one gives negatives only, over the whole
rollout.

Where the cut lies: highway-env ends a natural episode at the first contact of two boxes, so the
natural positives end 0.1 ... 3 s before the first touch. The judge's collision (IoU > 0.02)
comes later, once the boxes are well inside each other (in a slow side-swipe, seconds later);
windows ending at it would show overlapping boxes, which no natural positive does. By default
(`cut="contact"`) the recording is therefore cut at the onset of that contact: the first step of
the unbroken run of box overlap (IoU > 0) with the collision partner that leads to the judged
collision; `cut="judge"` cuts at the judged step itself. Records whose ego already collided before the attack time t0 are skipped (the attack
was moot there), as are records without tracks (no candidate, errors).

Layout: the guard dataset's (`riskmap.guard.dataset`): GUARD_DIR/jobs/<split>_adv_<env>_<planner>_
<selector>_s<scene seed>_<scene>.npz + .json (atomic; `--resume` skips those present), so that
`riskmap guard train` and `load_split` read them next to natural windows in the same directory;
GUARD_DIR/adversary_<split>.json sums up one export. Splits: every record goes to `split`
(e.g. "adversarial" for held-out attack scenes), except that with `val_fraction` > 0 the last
share of each attack run's scenes goes to "val" (e.g. `--split train --val-fraction 0.2` for
attack scenes recorded for training).
"""

from __future__ import annotations

import json
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from rasterize.scene import AgentKind
from rasterize.tracks import Tracks
from riskmap.guard.dataset import (
    GuardCollectConfig,
    extract_windows,
    finished_job,
    positives_within,
    split_counts,
)
from riskmap.guard.features import MAX_HORIZON_S
from riskmap.infra.atomic import write_json, write_npz
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import lock_out_dir

SPLIT_CHARS = set("abcdefghijklmnopqrstuvwxyz0123456789")
CUTS = ("contact", "judge")


@dataclass(frozen=True)
class GuardDataConfig:
    split: str = "adversarial"
    val_fraction: float = 0.0       # share of each run's scenes (the last ones) that go to "val"
    skip_scenes: int = 0            # the first scenes of every run are left out (kept for evaluation)
    cut: str = "contact"            # where a collision cuts the recording (module docstring)
    # Window settings shared with `riskmap guard collect` (control rate, max d_s, negatives).
    windows: GuardCollectConfig = field(default_factory=GuardCollectConfig)

    def __post_init__(self) -> None:
        if not self.split or not set(self.split) <= SPLIT_CHARS:
            raise InputError(f"--split {self.split!r} must be a non-empty lower-case word (letters, digits)")
        if self.cut not in CUTS:
            raise InputError(f"--cut {self.cut!r} must be one of {', '.join(CUTS)}")
        if not 0.0 <= self.val_fraction < 1.0:
            raise InputError(f"--val-fraction {self.val_fraction} must be in [0, 1)")
        if self.skip_scenes < 0:
            raise InputError(f"--skip-scenes {self.skip_scenes} must be ≥ 0")


@dataclass(frozen=True)
class AttackRun:
    """One `adversary attack` output directory: its settings and its attack records (by name)."""

    path: Path
    planner: str
    selector: str
    scenes: Path
    seed: int
    names: tuple[str, ...]


def read_attack_run(path: Path) -> AttackRun:
    path = Path(path)
    try:
        meta = json.loads((path / "run.json").read_text())
        planner, selector = meta["planner"], meta["config"]["selector"]
        scenes, seed = Path(meta["scenes"]), int(meta["seed"])
    except (OSError, ValueError, KeyError, TypeError):
        raise InputError(f"--attacks {path} holds no readable run.json; point it at an `adversary "
                         "attack --out` directory") from None
    names = tuple(sorted(p.stem for p in (path / "attacks").glob("*.json")))
    if not names:
        raise InputError(f"--attacks {path} holds no attack records yet (attacks/*.json); run "
                         f"`adversary attack --out {path}` first")
    return AttackRun(path, planner, selector, scenes, seed, names)


def read_attack(run: AttackRun, name: str) -> dict:
    """Attack record `name` of `run`; a damaged one is an InputError naming it."""
    path = run.path / "attacks" / f"{name}.json"
    try:
        attack = json.loads(path.read_text())
        if not isinstance(attack, dict) or (attack.get("status") == "ok" and "scene" not in attack):
            raise ValueError("not an attack record")
    except (OSError, ValueError):
        raise InputError(f"attack record {path} is damaged; delete it and run `adversary attack "
                         f"--resume --out {run.path}` to attack that scene again") from None
    return attack


def job_name(split: str, env_id: str, planner: str, selector: str, scene_seed: int, scene: str) -> str:
    env = env_id.split("-")[0]
    return f"{split}_adv_{env}_{planner.split(':')[0]}_{selector}_s{scene_seed}_{scene}"


def recorder_kinds(log_kinds: np.ndarray, log_ids: np.ndarray) -> np.ndarray:
    """Kinds [A] of the rollout's recorder agents: their log agent's (a vehicle when unmatched)."""
    kinds = np.full(len(log_ids), int(AgentKind.VEHICLE), dtype=np.asarray(log_kinds).dtype)
    matched = log_ids >= 0
    kinds[matched] = np.asarray(log_kinds)[log_ids[matched]]
    return kinds


def collision_step(metrics: dict, dt_s: float) -> int | None:
    """The rollout step of the ego's first collision from t0 on (any vehicle), or None."""
    if not metrics["collision_any"]:
        return None
    return round(metrics["collision_any_time_s"] / dt_s)


def contact_onset(tracks: Tracks, ego: int, step: int) -> tuple[int, int]:
    """(first step, partner) of the unbroken box overlap between the ego and the agent it overlaps
    most at `step` in `tracks`, walking back from `step`."""
    from adversary.crash.judge import box_iou

    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes

    def iou(agent: int, k: int) -> float:
        if not (valid[agent, k] and valid[ego, k]):
            return 0.0
        return box_iou(states[ego, k], sizes[ego], states[agent, k], sizes[agent])

    others = [a for a in range(len(states)) if a != ego and valid[a, step]]
    partner = max(others, key=lambda a: iou(a, step))
    if iou(partner, step) <= 0.0:
        raise InputError(f"the ego overlaps no box at step {step}; the collision step is wrong")
    first = step
    while first > 0 and iou(partner, first - 1) > 0.0:
        first -= 1
    return first, partner


def rollout_windows(record, attack: dict, planner, config: GuardCollectConfig, rng: np.random.Generator,
                    cut_at: str = "contact") -> tuple[dict[str, np.ndarray] | None, dict]:
    """(windows as `extract_windows`, meta) of one attack record; windows None when skipped."""
    from adversary.crash.attack import replan_hz_of
    from adversary.crash.judge import judge, rollout

    tracks = np.asarray(attack["tracks"], dtype=np.float64)
    rows = attack["metrics"]["spliced_rows"]
    adv_row = int(attack["adversary_row"])
    result = rollout(record, tracks, rows, planner, attack["planner"], replan_hz=replan_hz_of(attack))
    metrics = judge(record, tracks, rows, adv_row, planner, attack["planner"], result=result)
    adversary = int(result.row_ids(record)[adv_row])
    meta = {"adversary_collision": bool(metrics["collision"]), "collision_time_s": metrics["collision_time_s"],
            "collision_any_time_s": metrics["collision_any_time_s"],
            "collision_before_t0": bool(metrics["collision_before_t0"]),
            # the rollout is deterministic: the re-drive must meet the attack's own judgement
            "matches_attack": metrics["collision_time_s"] == attack["metrics"]["collision_time_s"],
            "adversary_recorder_id": adversary, "ego_recorder_id": int(result.ego)}
    if metrics["collision_before_t0"]:
        return None, {**meta, "skipped": "the ego collided before t0"}
    judged = collision_step(metrics, result.dt_s)
    cut = judged
    if judged is not None and cut_at == "contact":
        cut, _ = contact_onset(result.tracks, result.ego, judged)
    end = result.states.shape[1] if cut is None else cut + 1
    kinds = recorder_kinds(record.log.kinds, result.log_ids)
    cut_tracks = Tracks(result.states[:, :end], result.valid[:, :end], result.sizes, kinds)
    windows = extract_windows(cut_tracks, result.ego, cut is not None, config, rng)
    partners = sorted({int(i) for i in windows["neighbour"][np.isfinite(windows["ttc_s"])]})
    meta.update({"collided": cut is not None, "cut_step": cut, "judged_step": judged, "cut_at": cut_at,
                 "first_collision_is_adversary": cut is not None and metrics["collision"]
                 and metrics["collision_time_s"] == metrics["collision_any_time_s"],
                 "positive_partners": partners, "partner_is_adversary": partners == [adversary] if partners else None,
                 "windows": len(windows["ttc_s"]), "positives": positives_within(windows["ttc_s"], MAX_HORIZON_S)})
    return windows, meta


def export(attack_dirs: list[Path], out: Path, config: GuardDataConfig = GuardDataConfig(),
           resume: bool = False, progress: bool = True) -> dict:
    """Windows of every attack record under `attack_dirs` into `out` (module docstring)."""
    from tqdm import tqdm

    from adversary.crash.scenes import load_record
    from riskmap.registry import cached_planner

    runs = [read_attack_run(Path(d)) for d in attack_dirs]
    todo = [(run, i, name) for run in runs for i, name in enumerate(run.names) if i >= config.skip_scenes]
    # Every record and the scene of every attack that will be driven again are read before
    # --out exists: a damaged one stops the export with nothing written.
    attacks = {(run.path, name): read_attack(run, name) for run, _, name in todo}
    for run, _, name in todo:
        if attacks[run.path, name].get("status") == "ok":
            load_record(run.scenes / f"{name}.npz")
    # One writer per guard dataset; it also removes the temporary files a killed writer left.
    lock_out_dir(Path(out))
    jobs_dir = Path(out) / "jobs"
    metas = []
    for run, i, name in tqdm(todo, disable=not progress, desc="guard data"):
        attack = attacks[run.path, name]
        if attack.get("status") != "ok":
            metas.append({"attack": str(run.path / "attacks" / name), "skipped": attack.get("status")})
            continue
        n_val = round(config.val_fraction * (len(run.names) - config.skip_scenes))
        split = "val" if i >= len(run.names) - n_val else config.split
        scene = attack["scene"]
        job = job_name(split, scene["env_id"], run.planner, run.selector, scene["scene_seed"], name)
        path, meta_path = jobs_dir / f"{job}.npz", jobs_dir / f"{job}.json"
        done = finished_job(jobs_dir, job, out, resume)
        if done is not None:
            metas.append(done)
            continue
        record = load_record(run.scenes / f"{name}.npz")
        planner = cached_planner(run.planner, run.seed)
        rng = np.random.default_rng([zlib.crc32(job.encode()), 11])
        windows, meta = rollout_windows(record, attack, planner, config.windows, rng, config.cut)
        meta = {"split": split, "job": job, "attack": str(run.path / "attacks" / f"{name}.json"),
                "planner": run.planner, "selector": run.selector, "env_id": scene["env_id"],
                "scene_seed": scene["scene_seed"], "episode": scene["episode"], **meta}
        if windows is None:
            metas.append(meta)
            continue
        write_npz(path, windows)
        write_json(meta_path, meta)
        metas.append(meta)
    used = [m for m in metas if "windows" in m]
    crashed = [m for m in used if m["collided"]]
    summary = {"config": asdict(config), "attack_runs": [str(r.path) for r in runs],
               "records": len(metas), "used": len(used),
               "skipped": {why: sum(m.get("skipped") == why for m in metas)
                           for why in sorted({str(m["skipped"]) for m in metas if "skipped" in m})},
               "splits": split_counts(used),
               "crashes_with_adversary_first": sum(bool(m["first_collision_is_adversary"]) for m in crashed),
               "partner_is_adversary": sum(m["partner_is_adversary"] is True for m in crashed),
               "matches_attack": sum(bool(m["matches_attack"]) for m in used), **provenance()}
    write_json(Path(out) / f"adversary_{config.split}.json", summary)
    return summary
