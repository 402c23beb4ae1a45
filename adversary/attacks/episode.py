"""How a campaign job drives its episode and what it records of it, shared by every attack.

`drive_with_hooks` drives the job's scene with an attack's episode hooks (categories baseline,
rule); `record_of` turns a driven episode and its `EpisodeMonitor` into the job record's fields,
`artifact_of` into the npz the report's gallery draws. `job` is a campaign job
(adversary.campaign.job.Job), read by attribute.

What a guard did (riskmap.guard.guarded: `guard:SPEC`, `guard-always:SPEC`) is read in one place,
`guard_counts`, by every attack: the record fields `GUARD_FIELDS` hold the decision frames, the
interventions and the hard brakes of the job's judged drive, or None when no guard drove.
"""

from __future__ import annotations

import io
from dataclasses import replace

import numpy as np

from adversary.attacks.monitor import EpisodeMonitor
from riskmap.registry import cached_planner
from riskmap.sim.loop.plan import drives_itself, traits_of
from riskmap.sim.records.record import EpisodeRecord

# The guard's counts of one driven episode in a job record (None: no guard drove the ego).
GUARD_FIELDS = ("guard_frames", "guard_interventions", "guard_hard")


def guard_of(planner):
    """The guard of a guarded planner (`GuardedPlanner`, `GuardedHumanDriver`: its `guard`, a
    `riskmap.guard.guarded.Guard`), also through a wrapper that forwards attributes
    (`RecordingPlanner`); None for any other planner. Found by duck type (a `guard` with a
    `summary()`), so that the attacks do not import the guard and its models."""
    guard = traits_of(planner).guard
    return guard if callable(getattr(guard, "summary", None)) else None


def clear_guard(planner) -> None:
    """Zero the guard's counts before a job drives: a drive that hands the ego to the guarded
    planner resets them itself, but one that replaces it (the recordings' IDM for `guard:idm` on
    a recorded scene) never does, and a cached planner would otherwise report an earlier job's."""
    guard = guard_of(planner)
    if guard is not None:
        guard.reset()


def guard_counts(planner) -> dict:
    """The record fields `GUARD_FIELDS` of the episode `planner` drove last: its guard's decision
    frames, interventions and hard-brake frames (`Guard.summary()`); all None without a guard."""
    guard = guard_of(planner)
    if guard is None:
        return dict.fromkeys(GUARD_FIELDS)
    summary = guard.summary()
    return {"guard_frames": int(summary.get("frames", 0)),
            "guard_interventions": int(summary.get("interventions", 0)),
            "guard_hard": int(summary.get("hard", 0))}


def attack_seed(job) -> int:
    """The seed of the job's attack: the same for every attack of one (planner seed, scene)."""
    return int(np.random.SeedSequence([job.planner_seed, job.scene_seed, job.episode])
               .generate_state(1)[0])


class RecordingPlanner:
    """Passes plans through and keeps, for the report, the last (scene, plan) and the risk map
    of every plan (with its scene's time), for planners that make one."""

    def __init__(self, planner):
        self.inner = planner
        self.last = None
        self.risk_maps: list[tuple[float, np.ndarray]] = []

    def __getattr__(self, name):
        # The planner's optional declarations (requires_log, set_log, attach, name, ...) are its
        # own: the rollout reads them from whatever it is given.
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def raster(self):
        return self.inner.raster

    def reset(self, scene) -> None:
        self.last = None
        self.risk_maps = []
        self.inner.reset(scene)

    def plan(self, scene):
        plan = self.inner.plan(scene)
        self.last = (scene, plan)
        if getattr(plan, "risk_map", None) is not None:
            self.risk_maps.append((float(scene.time_s), np.asarray(plan.risk_map, np.float16)))
        return plan


def artifact_of(monitor: EpisodeMonitor, recording: RecordingPlanner | None, env_id: str) -> bytes:
    """npz bytes: the final scene with 8 s of history at the recording's rate (every recorded
    step: the report's frames and animation), the last planning scene and its plan, and the risk
    map of every plan (`plans__time_s` [P], `plans__risk_map` [P, G, G] float16) where the
    planner makes one. Stores written before the frames were kept hold the final scene at 0.5 s
    steps and no `plans__` arrays; the report reads both."""
    from rasterize.frames import world_from_highway_env

    run = monitor.run
    final = run.recorder.scene(run.recorder.num_steps - 1, history_s=8.0, future_s=0.0,
                               dt_s=run.recorder.dt_s, source=env_id)
    adversary = monitor.attack.adversary
    where = None if adversary is None else world_from_highway_env(adversary.position)
    return npz_bytes(scene_arrays(final, where, recording))


def scene_arrays(final, adversary_xy: np.ndarray | None, recording: RecordingPlanner | None) -> dict:
    """The artifact arrays of `artifact_of` from the final scene, the adversary's world position
    at its last step (None: no adversary) and the recording planner."""
    from rasterize.scene_io import pack_scenes

    arrays = {f"final__{k}": v for k, v in pack_scenes([final]).items()}
    index = -1
    if adversary_xy is not None:
        offsets = np.linalg.norm(final.states[:, final.current_index, :2] - adversary_xy, axis=1)
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
    if recording is not None and recording.risk_maps:
        arrays["plans__time_s"] = np.array([t for t, _ in recording.risk_maps], np.float32)
        arrays["plans__risk_map"] = np.stack([m for _, m in recording.risk_maps])
    return arrays


def npz_bytes(arrays: dict) -> bytes:
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


PLAN_TIMES = ("plan_ms_median", "plan_ms_mean", "plan_ms_p90")


def job_fields(record: EpisodeRecord) -> dict:
    """A job's record fields from its `EpisodeRecord`. The planner is left out: the job record
    names it by its SPEC (adversary.campaign.job.Job.describe), not by class. The plan times go
    under "timing" with the job's other machine-dependent numbers, so that the rest of a record
    is the same on every run of the job."""
    fields = record.as_dict()
    del fields["planner"]
    plan_times = {name: fields.pop(name) for name in PLAN_TIMES}
    fields["timing"] = {**plan_times, **fields.get("timing", {})}
    return fields


def record_of(episode: dict, monitor: EpisodeMonitor, extra: dict, planner=None) -> dict:
    """The job's measurements from one driven episode (`drive_episode`'s record) and its monitor;
    `planner`: what drove it, read right after the drive for its guard's counts (`guard_counts`)."""
    from riskmap.sim.records.alternatives import ego_only_solution
    from riskmap.sim.records.failures import classify_run

    solution = failure = None
    if episode["collided"] and monitor.collision_step is not None:
        recorder = monitor.run.recorder
        solution = ego_only_solution(recorder.tracks(), recorder.ego_id, monitor.collision_step,
                                     monitor.run.dt)
        partner = monitor.collision.get("partner_id")
        failure = None if partner is None else classify_run(
            monitor.run, monitor.attack.adversary, (monitor.collision_step, partner), monitor.adversary_off_road)
    driven = EpisodeRecord.from_dict(episode)
    return job_fields(replace(driven, extra={
        **monitor.summary(),
        "solution_found": solution,
        "failure": failure,
        "env_seed": episode["env_seed"],
        **guard_counts(planner),
        # Optional, attack-specific numbers (e.g. a search's generations and Pareto front).
        "attack_extra": extra,
    }))


def drive_with_hooks(job, factory) -> tuple[dict, bytes]:
    """Drive the job's scene with the hooks `factory(params, seed)` makes (categories baseline,
    rule)."""
    from riskmap.sim.loop.rollout import DriveHooks
    from riskmap.sim.worlds.episode import cached_env
    from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

    config = DriveConfig(job.env_id, episodes=job.episode + 1, seed=job.scene_seed,
                         control_hz=job.budget.control_hz, replan_hz=job.budget.replan_hz,
                         episode_s=job.budget.episode_s)
    planner = cached_planner(job.planner, job.planner_seed)
    env = cached_env(job.env_id, job.budget.control_hz)
    recording = None if drives_itself(planner) else RecordingPlanner(planner)
    clear_guard(planner)
    attack = factory(job.attack_params, attack_seed(job))
    monitor = EpisodeMonitor(attack, job.safety, job.budget.control_hz)
    episode = drive_episode(env, recording or planner, config,
                            job.episode, hooks=DriveHooks(on_reset=monitor.start, on_step=monitor.step))
    extra = attack.extra() if hasattr(attack, "extra") else {}
    return (record_of(episode, monitor, extra, recording or planner),
            artifact_of(monitor, recording, job.env_id))
