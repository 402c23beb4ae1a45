"""One stress-test job: (planner SPEC, env id, scene, attack + params) -> one result record.

`run_job` is the only function the execution backends call; it is a plain top-level function of
picklable arguments, so a process pool and Ray run exactly the same code. Results depend only on
the job (fresh episode from its seed, planner state reset per episode), never on which worker or
in which order jobs run, so a resumed or distributed campaign gives the same numbers.

Attacks of category "search" do not perturb the job's scene through episode hooks: their job runs
a seeded scenario search against the planner and replays the most critical scenario found
(`_search_and_replay`, adversary.search_attack); the `crash` attack (category "selection") runs
CRASH on the job's recorded scene (`_crash`, adversary.crash_attack); every other attack drives
the scene with its hooks (`_drive`).
"""

from __future__ import annotations

import hashlib
import io
import json
import re
import time
import traceback
from dataclasses import dataclass

import numpy as np

from adversary.attacks import attack_entry, make_attack
from adversary.monitor import EpisodeMonitor, SafetyConfig
from adversary.validation import to_plain

# Per-process caches: loading a checkpoint or making an env costs seconds; both are reset per
# episode (planner.reset, env.reset(seed)), so reuse does not change results.
_PLANNERS: dict = {}
_ENVS: dict = {}


@dataclass(frozen=True)
class Budget:
    episode_s: float | None = None    # simulated seconds per episode; None: the family's default
    control_hz: int = 10              # simulation and control rate
    replan_hz: int = 2


@dataclass(frozen=True)
class Job:
    planner: str              # SPEC (riskmap.registry)
    env_id: str
    scene_seed: int           # the scene is episode `episode` of `riskmap drive --seed scene_seed`
    episode: int
    attack: str               # the attack's label in the campaign
    attack_name: str          # its registered name
    attack_params: object     # its frozen params dataclass
    planner_seed: int
    budget: Budget
    safety: SafetyConfig

    @property
    def job_id(self) -> str:
        """Readable and unique: the key fields, then a hash of every field."""
        digest = hashlib.sha1(json.dumps(to_plain(self), sort_keys=True).encode()).hexdigest()[:10]
        slug = re.sub(r"[^A-Za-z0-9]+", "-", f"{self.planner}_{self.env_id}_s{self.scene_seed}"
                      f"e{self.episode}_{self.attack}").strip("-")
        return f"{slug[-80:]}-{digest}"

    def describe(self) -> dict:
        entry = attack_entry(self.attack_name)
        return {"job_id": self.job_id, "planner": self.planner, "env_id": self.env_id,
                "scene_seed": self.scene_seed, "episode": self.episode, "attack": self.attack,
                "attack_name": self.attack_name, "attack_category": entry.category,
                "attack_params": to_plain(self.attack_params)}


class RecordingPlanner:
    """Passes plans through and keeps the last (scene, plan) for the report's gallery."""

    def __init__(self, planner):
        self.inner = planner
        self.last = None

    @property
    def raster(self):
        return self.inner.raster

    def reset(self, scene) -> None:
        self.last = None
        self.inner.reset(scene)

    def plan(self, scene):
        plan = self.inner.plan(scene)
        self.last = (scene, plan)
        return plan


def _planner(spec: str, seed: int):
    from riskmap.registry import make_planner

    if (spec, seed) not in _PLANNERS:
        _PLANNERS[spec, seed] = make_planner(spec, seed=seed)
    return _PLANNERS[spec, seed]


def _env(env_id: str, control_hz: int):
    from riskmap.episode import make_env

    if (env_id, control_hz) not in _ENVS:
        _ENVS[env_id, control_hz] = make_env(env_id, control_hz)
    return _ENVS[env_id, control_hz]


def _artifact(monitor: EpisodeMonitor, recording: RecordingPlanner | None, env_id: str) -> bytes:
    """npz bytes: the final scene with 8 s of history, the last planning scene and its plan."""
    from rasterize.frames import world_from_highway_env
    from rasterize.scene_io import pack_scenes

    run = monitor.run
    final = run.recorder.scene(run.recorder.num_steps - 1, history_s=8.0, future_s=0.0,
                               source=env_id)
    arrays = {f"final__{k}": v for k, v in pack_scenes([final]).items()}
    adversary = monitor.attack.adversary
    index = -1
    if adversary is not None:
        where = world_from_highway_env(adversary.position)
        offsets = np.linalg.norm(final.states[:, final.current_index, :2] - where, axis=1)
        offsets[~final.valid[:, final.current_index]] = np.inf
        index = int(np.argmin(offsets)) if offsets.min() < 1e-3 else -1
    arrays["adversary_index"] = np.array(index)
    if recording is not None and recording.last is not None:
        scene, plan = recording.last
        arrays.update({f"plan_scene__{k}": v for k, v in pack_scenes([scene.past()]).items()})
        arrays["plan__waypoints"] = plan.waypoints
        for name in ("risk_map", "svf"):
            if getattr(plan, name) is not None:
                arrays[f"plan__{name}"] = np.asarray(getattr(plan, name), np.float32)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def _drive(job: Job) -> tuple[dict, bytes]:
    """Drive the job's scene with its attack's hooks (categories baseline, rule)."""
    from riskmap.drive import DriveConfig, DriveHooks, drive_episode
    from riskmap.registry import HumanDriver

    config = DriveConfig(job.env_id, episodes=job.episode + 1, seed=job.scene_seed,
                         control_hz=job.budget.control_hz, replan_hz=job.budget.replan_hz,
                         episode_s=job.budget.episode_s)
    planner = _planner(job.planner, job.planner_seed)
    env = _env(job.env_id, job.budget.control_hz)
    recording = None if isinstance(planner, HumanDriver) else RecordingPlanner(planner)
    attack_seed = int(np.random.SeedSequence([job.planner_seed, job.scene_seed, job.episode])
                      .generate_state(1)[0])
    attack = make_attack(job.attack_name, job.attack_params, attack_seed)
    monitor = EpisodeMonitor(attack, job.safety, job.budget.control_hz)
    episode = drive_episode(env, recording or planner, config,
                            job.episode, hooks=DriveHooks(on_reset=monitor.start, on_step=monitor.step))
    extra = attack.extra() if hasattr(attack, "extra") else {}
    return _record(episode, monitor, extra), _artifact(monitor, recording, job.env_id)


def _search_and_replay(job: Job) -> tuple[dict, bytes]:
    """Search scenarios against the job's planner, then replay the most critical one (category
    search; adversary.search_attack)."""
    from adversary.evaluate import run_scenario
    from adversary.search import search_in_process
    from adversary.search_attack import SEARCH_ENV_ID, ReplayedScenario, search_config, search_seed
    from adversary.templates import get_template
    from riskmap.registry import HumanDriver

    config = search_config(job.attack_name, job.attack_params, job.planner,
                           search_seed(job.planner_seed, job.scene_seed, job.episode))
    outcome = search_in_process(config)
    template = get_template(config.template)
    monitor = EpisodeMonitor(ReplayedScenario(), job.safety, config.evaluation.control_hz)
    recordings = []

    def wrap(planner):
        recordings.append(None if isinstance(planner, HumanDriver) else RecordingPlanner(planner))
        return recordings[0] or planner

    episode, _ = run_scenario(template, np.asarray(outcome.best_x), config.evaluation,
                              on_reset=monitor.start, on_step=monitor.step, wrap_planner=wrap)
    record = _record(episode, monitor, outcome.extra(template))
    return record, _artifact(monitor, recordings[0], SEARCH_ENV_ID)


def _crash(job: Job) -> tuple[dict, bytes | None]:
    """One CRASH attack on the job's recorded scene (adversary.crash_attack)."""
    from adversary.crash_attack import crash_job

    return crash_job(job, _planner(job.planner, job.planner_seed))


def _runner(attack_name: str):
    """The function that runs a job of this attack (module docstring)."""
    if attack_name == "crash":
        return _crash
    return _search_and_replay if attack_entry(attack_name).category == "search" else _drive


def _record(episode: dict, monitor: EpisodeMonitor, extra: dict) -> dict:
    """The job's measurements from one driven episode and its monitor."""
    from adversary.solution import ego_only_solution

    solution = None
    if episode["collided"] and monitor.collision_step is not None:
        states, valid, sizes, _ = monitor.run.recorder.arrays()
        solution = ego_only_solution(states, valid, sizes, monitor.run.recorder.ego_id,
                                     monitor.collision_step, monitor.run.dt)
    return {
        "collided": bool(episode["collided"]),
        "ego_off_road": bool(episode["off_road"]),
        **monitor.summary(),
        "solution_found": solution,
        "progress_m": episode["distance_m"],
        "mean_speed_mps": episode["mean_speed_mps"],
        "min_gap_m": episode["min_gap_m"] if np.isfinite(episode["min_gap_m"]) else None,
        "simulated_s": episode["simulated_s"],
        "env_seed": episode["env_seed"],
        "plan_calls": episode["plan_calls"],
        # Optional, attack-specific numbers (e.g. a search's generations and Pareto front).
        "attack_extra": extra,
        "timing": {"plan_ms_median": episode["plan_ms_median"]},
    }


def error_result(job: Job, error: BaseException, trace: str = "") -> dict:
    """The result of a job that failed: its record carries the error's first line."""
    record = {**job.describe(), "status": "error",
              "error": (f"{type(error).__name__}: {error}".splitlines() or [""])[0][:500],
              "traceback": trace[-2000:], "timing": {}}
    return {"record": record, "artifact": None}


def run_job(job: Job) -> dict:
    """{"record": dict, "artifact": npz bytes or None}; a failure is a record, never a raise."""
    started = time.perf_counter()
    try:
        import torch

        torch.set_num_threads(1)
        record, artifact = _runner(job.attack_name)(job)
        result = {"record": {**job.describe(), "status": "ok", "error": None, **record},
                  "artifact": artifact}
    except Exception as error:  # noqa: BLE001  (a failing job is recorded and the campaign goes on)
        result = error_result(job, error, traceback.format_exc(limit=4))
    result["record"]["timing"]["wall_s"] = time.perf_counter() - started
    return result
