"""`riskmap guard collect`: (ego, neighbour) accident windows from closed-loop episodes.

Every job is one episode: a scenario family, a driver of the ego (the IDM/MOBIL human or the
risk-map planner), a seed and an episode number, natural or with a scripted aggressive
neighbour (`riskmap.guard.aggressors`). Natural and aggressive runs of the same (seed, episode)
meet the same traffic: they are paired accident/normal runs.

Time to contact: every window stores `ttc_s`, the time from its last observed event to the ego's
contact with that neighbour (inf when they never touch). The label is derived when the data is
read (`load_split(..., horizon_s)`): positive when ttc_s ≤ horizon_s, so one collection serves
every label horizon up to MAX_HORIZON_S (3 s). A crash yields a window of its partner ending at
every control step of the 3 s before it; the other windows are the other pairs (and the partner
earlier) every 0.5 s, half the nearest by d_s and half at random, at most
`negatives_per_episode`, none later than 3 s before the end of an episode that did not crash
(their future is not known that far).

Decision frames: the windows the online guard would score — the 2 nearest neighbours by d_s every
0.5 s (`frame_*` arrays, `frame` = the frame's index, `frames` = how many frames the episode has).
Training picks the alert threshold on the validation frames for a target alert ratio.

Splits: train and validation episodes (seed `seed`) and the seen test episodes (seed `seed + 1`,
independent traffic) come from the seen families; the unseen test comes from the held-out family,
which no training or validation window comes from.

Layout: DIR/jobs/<job>.npz (atomic; `--resume` skips those present), DIR/manifest.json.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from rasterize.timebase import CONTROL_HZ
from rasterize.tracks import Tracks
from riskmap.guard.events import nearest_by_separation, scene_separations
from riskmap.guard.features import EDGE_DIM, MAX_HORIZON_S, NODE_DIM, OBSERVED, SEGMENT_S, window_features
from riskmap.infra.atomic import write_json, write_npz
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import claim_out_dir

PLANNER_CHECKPOINTS = {"highway-v0": "checkpoints/riskmap_highway",
                       "intersection-v0": "checkpoints/riskmap_intersection"}


@dataclass(frozen=True)
class GuardCollectConfig:
    seen_envs: tuple[str, ...] = ("highway-v0", "merge-v0", "intersection-v0")
    unseen_envs: tuple[str, ...] = ("roundabout-v0",)
    train_episodes: int = 40          # per seen family and driver, natural + aggressive each
    seen_test_episodes: int = 12
    unseen_episodes: int = 16
    val_fraction: float = 0.2         # the last episodes of the training seed
    planner_every: int = 4            # every k-th episode is driven by the risk-map planner too
    seed: int = 0
    episode_s: float = 20.0           # simulated seconds per episode (the crash comes early)
    control_hz: int = CONTROL_HZ
    max_ds_m: float = 50.0            # farther pairs are not interactions
    negatives_per_episode: int = 24
    frame_neighbours: int = 2         # scored per decision frame, as `GuardConfig.neighbours`

    def __post_init__(self) -> None:
        """Bad settings stop here, before `collect` claims --out."""
        import math

        from rasterize.config import family_of_env

        object.__setattr__(self, "seen_envs", tuple(self.seen_envs))
        object.__setattr__(self, "unseen_envs", tuple(self.unseen_envs))
        if not self.seen_envs:
            raise InputError("--seen-envs is empty; name at least one scenario family, e.g. highway-v0")
        for env_id in self.seen_envs + self.unseen_envs:
            family_of_env(env_id)          # an InputError naming the supported ids
        for name in ("train_episodes", "seen_test_episodes", "unseen_episodes", "planner_every",
                     "control_hz"):
            if getattr(self, name) < 1:
                raise InputError(f"{name} {getattr(self, name)}: must be at least 1")
        if not (math.isfinite(self.episode_s) and self.episode_s > 0):
            raise InputError(f"--episode-s {self.episode_s}: must be a positive number of seconds")
        if not 0 <= self.val_fraction < 1:
            raise InputError(f"val_fraction {self.val_fraction}: must be in [0, 1)")


@dataclass(frozen=True)
class Job:
    split: str            # train, val, seen, unseen
    env_id: str
    driver: str           # planner SPEC
    seed: int
    episode: int
    aggressive: bool

    @property
    def name(self) -> str:
        driver = self.driver.split(":")[0]
        kind = "agg" if self.aggressive else "nat"
        return f"{self.split}_{self.env_id}_{driver}_s{self.seed}_e{self.episode:04d}_{kind}"


def plan_jobs(config: GuardCollectConfig) -> list[Job]:
    jobs = []

    def add(split, env_id, seed, episodes):
        for episode in episodes:
            drivers = ["idm"]
            if env_id in PLANNER_CHECKPOINTS and episode % config.planner_every == 0:
                drivers.append(f"riskmap:{PLANNER_CHECKPOINTS[env_id]}")
            for driver in drivers:
                for aggressive in (False, True):
                    jobs.append(Job(split, env_id, driver, seed, episode, aggressive))

    n_val = round(config.train_episodes * config.val_fraction)
    for env_id in config.seen_envs:
        add("train", env_id, config.seed, range(config.train_episodes - n_val))
        add("val", env_id, config.seed, range(config.train_episodes - n_val, config.train_episodes))
        add("seen", env_id, config.seed + 1, range(config.seen_test_episodes))
    for env_id in config.unseen_envs:
        add("unseen", env_id, config.seed + 2, range(config.unseen_episodes))
    return jobs


def crash_partner(ds_last: np.ndarray) -> int:
    """The neighbour the ego hit: the smallest d_s at the crash step (overlap is negative)."""
    return int(np.argmin(ds_last))


def _features(tracks: Tracks, ego: int, pairs: list[tuple[int, int]], seg: int) -> dict:
    out = {"node_u": np.zeros((len(pairs), NODE_DIM), np.float32),
           "node_i": np.zeros((len(pairs), NODE_DIM), np.float32),
           "edge": np.zeros((len(pairs), OBSERVED, EDGE_DIM), np.float32),
           "mask": np.zeros((len(pairs), OBSERVED), bool)}
    for w, (i, k) in enumerate(pairs):
        out["node_u"][w], out["node_i"][w], out["edge"][w], out["mask"][w] = window_features(
            tracks, ego, i, k, seg)
    return out


def extract_windows(tracks: Tracks, ego: int, crashed: bool, config: GuardCollectConfig,
                    rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Windows and decision frames of one recorded episode (`tracks` as `TrafficRecorder.tracks()`,
    1/control_hz s; a crashed episode ends at its crash step). Keys: node_u, node_i, edge, mask,
    ttc_s, neighbour, last_step (the windows), frame_* and frame, frames (module docstring)."""
    seg = round(SEGMENT_S * config.control_hz)
    horizon = round(MAX_HORIZON_S * config.control_hz)
    valid, n_steps = tracks.valid, tracks.num_steps
    ds = scene_separations(tracks, ego)
    crash_step = n_steps - 1 if crashed else None
    partner = crash_partner(ds[:, -1]) if crashed else None
    positives = [(partner, k) for k in range(crash_step - horizon, crash_step)
                 if k >= 0 and valid[partner, k]] if crashed else []
    last_labelled = crash_step - 1 if crashed else n_steps - 1 - horizon
    negatives = [(int(i), k) for k in range(seg, last_labelled + 1, seg)
                 for i in np.flatnonzero(np.isfinite(ds[:, k]) & (ds[:, k] < config.max_ds_m))
                 if (int(i), k) not in positives]
    if len(negatives) > config.negatives_per_episode:
        order = np.argsort([ds[i, k] for i, k in negatives], kind="stable")
        half = config.negatives_per_episode // 2
        nearest = list(order[:half])
        rest = rng.choice(order[half:], config.negatives_per_episode - half, replace=False)
        negatives = [negatives[j] for j in sorted(nearest + list(rest))]
    pairs = positives + negatives
    out = _features(tracks, ego, pairs, seg)
    out["ttc_s"] = np.array([(crash_step - k) / config.control_hz if i == partner else np.inf
                             for i, k in pairs], np.float32)
    out["neighbour"] = np.array([i for i, _ in pairs], np.int32)
    out["last_step"] = np.array([k for _, k in pairs], np.int32)
    frame_steps = range(seg, n_steps, seg)
    frame_pairs, frame_of = [], []
    for f, k in enumerate(frame_steps):
        for i in nearest_by_separation(ds[:, k], config.frame_neighbours):
            frame_pairs.append((i, k))
            frame_of.append(f)
    out.update({f"frame_{key}": value for key, value in
                _features(tracks, ego, frame_pairs, seg).items()})
    out["frame"] = np.array(frame_of, np.int32)
    out["frames"] = np.array([len(frame_steps)], np.int32)
    return out


class _KeepRun:
    """Episode hook that keeps the `Episode` so that its recording can be read afterwards."""

    run = None

    def __call__(self, run) -> None:
        self.run = run


def run_job(job: Job, config: GuardCollectConfig, env, planner) -> tuple[dict, dict]:
    from riskmap.guard.aggressors import AggressorHook
    from riskmap.sim.loop.rollout import DriveHooks
    from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

    keep = _KeepRun()
    hooks = (keep, AggressorHook()) if job.aggressive else (keep,)
    drive_config = DriveConfig(job.env_id, job.episode + 1, seed=job.seed, control_hz=config.control_hz,
                               episode_s=config.episode_s)
    record = drive_episode(env, planner, drive_config, job.episode, hooks=DriveHooks(on_ready=hooks))
    rng = np.random.default_rng([job.seed, job.episode, int(job.aggressive), 7])
    windows = extract_windows(keep.run.recorder.tracks(), keep.run.recorder.ego_id, bool(record["collided"]),
                              config, rng)
    meta = {**asdict(job), "collided": bool(record["collided"]), "simulated_s": record["simulated_s"],
            "aggressor": bool(hooks[-1].aggressor is not None) if job.aggressive else False,
            "windows": len(windows["ttc_s"]), "positives": positives_within(windows["ttc_s"], MAX_HORIZON_S)}
    return windows, meta


def collect(config: GuardCollectConfig, out: Path, resume: bool = False, progress: bool = True) -> dict:
    from tqdm import tqdm

    from riskmap.registry import make_planner
    from riskmap.sim.worlds.episode import make_env

    out = Path(out)
    jobs_dir = out / "jobs"
    claim_out_dir(out, holds="guard data", marker="jobs", resume=resume, settings_file="settings.json",
                  settings={"config": asdict(config)})
    envs, planners, metas = {}, {}, []
    for job in tqdm(plan_jobs(config), disable=not progress, desc="guard collect"):
        path = jobs_dir / f"{job.name}.npz"
        meta_path = jobs_dir / f"{job.name}.json"
        if resume and path.exists() and meta_path.exists():
            metas.append(json.loads(meta_path.read_text()))
            continue
        if job.env_id not in envs:
            envs[job.env_id] = make_env(job.env_id, config.control_hz)
        # One planner per driver and seed: a job's episode is its own, whichever jobs this
        # process ran before it (a resumed run starts further on).
        if (job.driver, job.seed) not in planners:
            planners[job.driver, job.seed] = make_planner(job.driver, seed=job.seed)
        windows, meta = run_job(job, config, envs[job.env_id], planners[job.driver, job.seed])
        write_npz(path, windows)
        write_json(meta_path, meta)
        metas.append(meta)
    manifest = {"config": asdict(config), "jobs": len(metas), "splits": split_counts(metas), **provenance()}
    write_json(out / "manifest.json", manifest)
    return manifest


def finished_job(jobs_dir: Path, job: str, out: Path, resume: bool) -> dict | None:
    """The meta of job `job` when both its files exist (a resumed export skips it), else None; a job
    that exists without --resume is an InputError naming --out."""
    npz, meta = Path(jobs_dir) / f"{job}.npz", Path(jobs_dir) / f"{job}.json"
    if not (npz.exists() or meta.exists()):
        return None
    if not resume:
        raise InputError(f"--out {out} already holds {job}; pass --resume to continue or choose another --out")
    return json.loads(meta.read_text()) if npz.exists() and meta.exists() else None


def split_counts(metas: list[dict]) -> dict:
    counts = {}
    for m in metas:
        c = counts.setdefault(m["split"], {"episodes": 0, "crashes": 0, "windows": 0, "positives": 0})
        c["episodes"] += 1
        c["crashes"] += int(m["collided"])
        c["windows"] += m["windows"]
        c["positives"] += m["positives"]
    return counts


WINDOW_KEYS = ("node_u", "node_i", "edge", "mask", "ttc_s")
FRAME_KEYS = ("frame_node_u", "frame_node_i", "frame_edge", "frame_mask", "frame", "frames")


def positives_within(ttc_s: np.ndarray, horizon_s: float) -> int:
    return int(labels_for(ttc_s, horizon_s).sum())


def labels_for(ttc_s: np.ndarray, horizon_s: float) -> np.ndarray:
    """1 where the ego touches the window's neighbour within `horizon_s` of its last event [W] int8.
    (The tolerance absorbs float32 rounding of ttc_s = steps / control_hz.)"""
    if not 0 < horizon_s <= MAX_HORIZON_S:
        raise InputError(f"label horizon {horizon_s} s: must be in (0, {MAX_HORIZON_S:g}] s, the "
                         "longest the guard data records")
    return (np.asarray(ttc_s) <= horizon_s + 1e-4).astype(np.int8)


def load_job(path: Path) -> dict[str, np.ndarray]:
    """The windows of one job file; a damaged one (unreadable, lacking arrays, NaN or inf
    features) is an InputError naming it."""
    from riskmap.infra.atomic import read_npz

    fix = ("delete it (and its .json) and write it again: `riskmap guard collect --resume`, or "
           "`adversary guard-data --resume` for attack windows")
    arrays = read_npz(path, "guard windows", fix)
    if "label" in arrays and "ttc_s" not in arrays:
        raise InputError(f"guard windows {path} were written by an older version (a fixed 1 s label, "
                         "no time to contact); collect the dataset again into a new directory")
    missing = [key for key in WINDOW_KEYS if key not in arrays]
    if missing:
        raise InputError(f"guard windows {path} lack {', '.join(missing)}; {fix}")
    if arrays["edge"].shape[-1] != EDGE_DIM:
        raise InputError(f"guard windows {path} have {arrays['edge'].shape[-1]} edge features, this version "
                         f"{EDGE_DIM}; collect the dataset again into a new directory")
    for key in ("node_u", "node_i", "edge") + tuple(k for k in FRAME_KEYS[:3] if k in arrays):
        if not np.isfinite(arrays[key]).all():
            raise InputError(f"guard windows {path} hold NaN/inf in {key}; {fix}")
    return arrays


def _split_paths(data: Path, split: str) -> list[Path]:
    if not Path(data).is_dir():
        raise InputError(f"--data {data} is not a guard dataset directory; make one with "
                         f"`riskmap guard collect --out {data}`")
    paths = sorted((Path(data) / "jobs").glob(f"{split}_*.npz"))
    if not paths:
        there = sorted({p.name.split("_", 1)[0] for p in (Path(data) / "jobs").glob("*_*.npz")})
        if there:
            raise InputError(f"no {split!r} windows under {data}/jobs; use one of the splits there: "
                             f"{', '.join(there)}")
        raise InputError(f"no {split!r} windows under {data}/jobs; run `riskmap guard collect --out {data}`")
    return paths


def load_split(data: Path, split: str, horizon_s: float) -> dict[str, np.ndarray]:
    """All windows of `split` concatenated, labelled for `horizon_s` (keys as `extract_windows`'
    windows, plus `label` and `job` indices)."""
    parts = [load_job(p) for p in _split_paths(data, split)]
    merged = {k: np.concatenate([p[k] for p in parts]) for k in WINDOW_KEYS}
    merged["label"] = labels_for(merged["ttc_s"], horizon_s)
    merged["job"] = np.concatenate([np.full(len(p["ttc_s"]), j) for j, p in enumerate(parts)])
    return merged


def load_frames(data: Path, split: str) -> dict[str, np.ndarray] | None:
    """The decision frames of `split` (keys node_u, node_i, edge, mask of the scored windows,
    `frame` = a global frame index, `frames` = the number of frames), or None when the split's
    files hold none (data written without them)."""
    parts = [load_job(p) for p in _split_paths(data, split)]
    if not all(k in p for p in parts for k in FRAME_KEYS):
        return None
    out = {k[len("frame_"):]: np.concatenate([p[k] for p in parts]) for k in FRAME_KEYS[:4]}
    offsets = np.cumsum([0] + [int(p["frames"][0]) for p in parts])
    out["frame"] = np.concatenate([p["frame"] + offsets[j] for j, p in enumerate(parts)])
    out["frames"] = int(offsets[-1])
    return out
