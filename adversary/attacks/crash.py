"""The CRASH attack of stress-test campaigns (category "selection"): pick an adversary in the job's
scene with a selector, generate its future with the traffic model against the planner under test,
judge the planner's closed-loop drive (adversary.crash). In a campaign config:

    attacks:
      - {name: crash, label: MAM+ASM, params: {selector: crash}}
      - {name: crash, label: DS, params: {selector: distance, iterations: 50}}

A job (planner, env, scene seed, episode) records the human's episode up to t0 + 6 s
(adversary.crash.scenes.record_attack_scene), runs one CRASH attack on it with the job's planner
(adversary.crash.attack.attack_records) and maps the judge's metrics onto the campaign record
(`crash_record`). Models are read from `traffic_model` / `selector_model`, where `{family}` stands
for the job's scenario family (highway, intersection, or a recorded family such as us101); the
defaults are the shipped checkpoints. On a recorded scenario family (adversary.attacks.recorded)
the scene is the job's recorded one, cut as `adversary scenes --commonroad` cuts it; its attack
time is the family's `t0` (`t0_s` here applies to highway-env scenes only).

Differences to the episode attacks, all visible in the record:
- the episode is t0 + 6 s long (8 s by default) at 10 Hz with a plan every 0.5 s, CRASH's own
  rates: the campaign's budget does not apply;
- collisions are judged on box overlap (IoU > 0.02) from t0 on (adversary.crash.judge), with the
  ego passing through other boxes; `collided` is any such collision (or one before t0),
  `collided_with_adversary` the CRASH/STRIVE collision; kinematic value, collision type and the
  solution check exist only for collisions with the adversary;
- distance_m and min_gap_m span t0 to the collision (the end without one); Safety % is not
  measured (None);
- a guarded planner's counts (guard_frames, guard_interventions, guard_hard) are those of the
  final drive, the one judged: `attack_records` drives it last, after every replanning rollout
  (one scene per job), and the drive resets the guard. A scene that is not attacked has none.
A scene that cannot be attacked (the human crashed or left the road before t0 + 6 s, no vehicle
within 60 m of the ego, or no candidate for the selector) gives an "ok" record with
`attacked: false` and the reason in `not_attacked`: it counts in every denominator as a job
without a collision, as in CRASH's own tables, and the report shows how many there were.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from adversary.attacks.base import HIGHWAY, RECORDED, AttackEntry
from adversary.attacks.episode import (
    GUARD_FIELDS,
    RecordingPlanner,
    attack_seed,
    clear_guard,
    guard_counts,
    job_fields,
    npz_bytes,
    scene_arrays,
)
from adversary.attacks.recorded import job_family
from rasterize.errors import InputError
from rasterize.timebase import HISTORY_S, PLAN_DT_S
from riskmap.infra.config_mapping import require
from riskmap.registry import cached_planner
from riskmap.sim.loop.plan import drives_itself
from riskmap.sim.loop.plan_checks import ImplausiblePlans
from riskmap.sim.records.metrics import coarse_collision_name
from riskmap.sim.records.record import EpisodeRecord, current_names

# CRASH's SELECTORS (adversary.crash.selection), spelt out so that reading a config does not
# import torch; tests/adversary/test_crash_attack.py checks the two agree.
SELECTORS = ("crash", "crash-no-mam", "distance", "distance+mam", "nearest", "random")
LEARNED_SELECTORS = ("crash", "crash-no-mam")
# HISTORY_S (rasterize.timebase, 2 s): the traffic model's history (adversary.crash.scenes.HISTORY_S)
WINDOW_DT_S = PLAN_DT_S            # its step (0.5 s)


@dataclass(frozen=True)
class CrashAttackParams:
    selector: str = "crash"            # crash (MAM+ASM), crash-no-mam (ASM), distance (STRIVE),
    #                                    distance+mam, nearest, random
    replan_every: int = 20             # k: the planner is re-run every k generation iterations
    iterations: int = 0                # Adam iterations; 0: CRASH's 300 (replay) / 200 (closed loop)
    traffic_model: str = "checkpoints/crash_traffic_{family}"      # {family}: the job's family
    selector_model: str = "checkpoints/crash_selector_{family}"    # dir with selector_mam, _no_mam
    t0_s: float = 2.0                  # attack time (s into the episode), >= 2 s of history

    def __post_init__(self) -> None:
        require(self.selector in SELECTORS, f"crash attack selector {self.selector!r} is unknown; "
                                            f"use one of {', '.join(SELECTORS)}")
        require(self.replan_every >= 1, f"crash attack replan_every must be >= 1, got {self.replan_every}")
        require(self.iterations >= 0, f"crash attack iterations must be >= 0 (0: CRASH's defaults), "
                                      f"got {self.iterations}")
        steps = self.t0_s / WINDOW_DT_S
        require(self.t0_s >= HISTORY_S and abs(steps - round(steps)) < 1e-9,
                f"crash attack t0_s={self.t0_s}: use a multiple of {WINDOW_DT_S} s that is >= {HISTORY_S}")
        for name in ("traffic_model", "selector_model"):
            try:
                getattr(self, name).format(family="highway")
            except (KeyError, IndexError, ValueError):
                raise InputError(f"crash attack {name} {getattr(self, name)!r}: the only placeholder "
                                 "allowed is {family}") from None

    def paths(self, env_id: str) -> tuple[Path, Path | None]:
        """(traffic model, selector dir or None when the selector needs none) for an env."""
        family = job_family(env_id)
        selector = (Path(self.selector_model.format(family=family))
                    if self.selector in LEARNED_SELECTORS else None)
        return Path(self.traffic_model.format(family=family)), selector

    def check_envs(self, envs: list[str]) -> None:
        """Every checkpoint the attack needs on `envs` exists (adversary.campaign.run checks this
        before a campaign starts)."""
        for env_id in envs:
            traffic, selector = self.paths(env_id)
            require(traffic.with_suffix(".json").is_file(),
                    f"crash attack on {env_id}: no traffic model {traffic} (.json/.safetensors); train "
                    "one with `adversary train-traffic` or set params.traffic_model")
            if selector is not None:
                missing = [n for n in ("selector_mam", "selector_no_mam")
                           if not (selector / f"{n}.json").is_file()]
                require(not missing, f"crash attack on {env_id}: {selector} holds no {missing[0] if missing else ''}; "
                                     "train selectors with `adversary train-selector`, set "
                                     "params.selector_model, or use selector distance")

    def attack_config(self):
        from adversary.crash.attack import AttackConfig

        extra = ({} if self.iterations == 0 else
                 {"iterations_replay": self.iterations, "iterations_closed_loop": self.iterations})
        return AttackConfig(selector=self.selector, replan_every=self.replan_every, **extra)


# Loaded models per process and (traffic model, selector dir): loading costs about a second and
# the models are only read, so reuse does not change results.
_MODELS: dict = {}


def _models(traffic: Path, selector: Path | None):
    from adversary.crash.attack import load_models

    key = (str(traffic), None if selector is None else str(selector))
    if key not in _MODELS:
        _MODELS[key] = load_models(traffic, selector)
    return _MODELS[key]


def _crash_fields(collided: bool, off_road: bool, distance_m: float | None, min_gap_m: float | None,
                  simulated_s: float | None, extra: dict, plans: ImplausiblePlans | None = None) -> dict:
    """Job record fields in the `EpisodeRecord` layout. The judge measures no speed and no plan
    times (None), and its episode is no campaign-seeded one (env_seed None); the guard's counts
    are None unless `extra` holds them. `plans`: the implausible plans over the scene's drives."""
    return job_fields(EpisodeRecord(
        planner="", collided=collided, off_road=off_road, simulated_s=simulated_s,   # planner: dropped
        distance_m=distance_m, mean_speed_mps=None, min_gap_m=min_gap_m, plan_calls=None,
        plan_ms_median=None, plan_ms_mean=None, plan_ms_p90=None, **(plans or ImplausiblePlans()).fields(),
        extra={**dict.fromkeys(GUARD_FIELDS), **extra, "env_seed": None}))


def _not_attacked(reason: str, extra: dict, timing: dict | None = None,
                  plans: ImplausiblePlans | None = None) -> dict:
    """The record of a job whose scene could not be attacked (module docstring)."""
    return _crash_fields(False, False, None, None, None, plans=plans, extra={
        "attacked": False, "not_attacked": reason,
        "has_adversary": False, "collided_with_adversary": False, "collision_type": None,
        "collision_time_s": None, "kinematic_mps": None, "adversary_off_road": None,
        "other_off_road": False, "encounters": None, "dangerous_encounters": None,
        "safety_pct": None, "solution_found": None, "failure": None,
        "attack_extra": extra, "timing": timing or {}})


def crash_record(result: dict, scene_s: float, guard: dict | None = None) -> dict:
    """Campaign record fields (adversary.campaign.job._record's) from one `attack_records` result;
    `guard`: the guard's counts of its final drive (`guard_counts`; None: no guard)."""
    extra = {"selector": result["selector"], "p": result["p"], "candidates": result["candidates"],
             "agents": result["agents"]}
    timing = {"attack_seconds": round(result["seconds"], 3)}
    plans = ImplausiblePlans()
    plans.add_record(result)              # the closed-loop drives ran even without a candidate
    if result["status"] != "ok":
        return _not_attacked(f"no candidate adversary for selector {result['selector']}", extra, timing,
                             plans)
    m = current_names(result["metrics"])
    extra.update({"adversary_row": result["adversary_row"], "adversary_log_id": result["adversary_log_id"],
                  "iterations": result["generation"]["iterations"],
                  "replans": result["generation"]["replans"],
                  "rollouts": result["timing"]["rollouts"], "collision_iou": m["collision_iou"],
                  "collision_any_row": m["collision_any_row"],
                  "collision_before_t0": m["collision_before_t0"],
                  "crash_collision_type": m["collision_type"]})
    adversary_hit = bool(m["collision"])
    collided = adversary_hit or bool(m["collision_any"]) or bool(m["collision_before_t0"])
    return _crash_fields(collided, bool(m["off_road"]), m["distance_m"], m["min_gap_m"], scene_s, {
        "attacked": True, "not_attacked": None, "has_adversary": True,
        "collided_with_adversary": adversary_hit,
        # In the campaign monitor's vocabulary, so that reports count both sources alike.
        "collision_type": coarse_collision_name(m["collision_type"]),
        "collision_time_s": m["collision_time_s"] if adversary_hit else m["collision_any_time_s"],
        "kinematic_mps": m["kinematic_value_mps"],
        "adversary_off_road": bool(m["adversary_off_road"]),
        "other_off_road": bool(m["other_off_road"]),
        "encounters": None, "dangerous_encounters": None, "safety_pct": None,
        "solution_found": m["solution_found"], "failure": m.get("failure"), **(guard or {}),
        "attack_extra": extra,
        "timing": {**timing, "generation_seconds": result["generation"]["batch_seconds"]}}, plans)


# What an attacked job keeps for `adversary export` (adversary.export.campaign), in its artifact:
# EXPORT_KEYS, every one prefixed "export__". attack_json: the attack record's small fields as
# `adversary attack` writes them (scene, planner, selector, adversary row and log id, collision,
# the judge's metrics) plus the scene's family; tracks / ego_states: its generated tracks and the
# ego's drive (the record's rounded values); scene_sha1: `scene_digest` of the scene attacked,
# which the exporter rebuilds from the scene (it is recorded again, not stored) and checks.
EXPORT_KEYS = ("export__attack_json", "export__tracks", "export__ego_states", "export__scene_sha1")
_EXPORT_FIELDS = ("scene", "planner", "selector", "status", "seed", "adversary_row", "adversary_log_id",
                  "collision", "metrics")


def scene_digest(record) -> str:
    """SHA-1 of an attack scene's log (states, validity, sizes) and window rows: the exporter
    checks that the scene it records again is the one the job attacked."""
    digest = hashlib.sha1()
    for array in (record.log.states, record.log.valid, record.log.sizes, record.agent_ids):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def export_arrays(result: dict, record) -> dict:
    """The artifact arrays `adversary export` needs of an attacked job (EXPORT_KEYS above)."""
    attack = {k: result[k] for k in _EXPORT_FIELDS if k in result}
    attack["family"] = record.family
    return {"export__attack_json": np.array(json.dumps(attack, sort_keys=True)),
            "export__tracks": np.asarray(result["tracks"], dtype=np.float64),
            "export__ego_states": np.asarray(result["ego_states"], dtype=np.float64),
            "export__scene_sha1": np.array(scene_digest(record))}


def rebuild_scene(attack: dict):
    """The `SceneRecord` a job attacked, recorded again from `attack` (its export__attack_json):
    a highway-env scene by driving the human again, a recorded one by cutting it from its
    recording again, exactly as `crash_job` does. InputError if it cannot be."""
    from adversary.crash.scene_source import scene_source
    from adversary.crash.scenes import AttackScene

    try:
        scene = AttackScene(**attack["scene"])
    except (KeyError, TypeError) as err:
        raise InputError(f"the job's export data names no scene ({err})") from None
    return scene_source(scene).record(scene, attack.get("family") or None)


def _artifact(result: dict, panel: Path, recording: RecordingPlanner | None, record=None) -> bytes | None:
    """npz bytes for the report: the attack's panel PNG (adversary.crash.panel) and, for an
    attacked scene, the final drive as the episode attacks store theirs (frames, risk maps) and
    what `adversary export` needs (`export_arrays`; with the scene `record`)."""
    arrays = {}
    if panel.is_file():
        arrays["crash_panel_png"] = np.frombuffer(panel.read_bytes(), dtype=np.uint8)
    if result.get("final_scene") is not None:
        arrays.update(scene_arrays(result["final_scene"], result.get("adversary_xy"), recording))
    if record is not None and result.get("status") == "ok":
        arrays.update(export_arrays(result, record))
    return npz_bytes(arrays) if arrays else None


def crash_job(job) -> tuple[dict, bytes | None]:
    """(record fields, artifact) of one campaign job of the crash attack (module docstring)."""
    from adversary.crash.attack import attack_records
    from adversary.crash.scene_source import scene_source
    from adversary.crash.scenes import AttackScene

    params: CrashAttackParams = job.attack_params
    recorded = getattr(job, "scene", None)
    scene = (recorded.attack_scene() if recorded is not None
             else AttackScene(job.env_id, job.scene_seed, job.episode, params.t0_s))
    try:
        record = scene_source(scene).record(scene, recorded.family if recorded is not None else None)
    except InputError as error:
        return _not_attacked(str(error), {"selector": params.selector}), None
    planner = cached_planner(job.planner, job.planner_seed)
    # The last rollout of an attack is its final drive: the recording keeps that drive's plans.
    recording = None if drives_itself(planner) else RecordingPlanner(planner)
    traffic, selector = params.paths(job.env_id)
    models = _models(traffic, selector)
    # The same seed as the episode attacks': only the random selector draws.
    seed = attack_seed(job)
    clear_guard(planner)
    with tempfile.TemporaryDirectory() as tmp:
        panel = Path(tmp) / "panel.png"
        [result] = attack_records([record], models, recording or planner, job.planner,
                                  params.attack_config(), [seed], [panel], keep_scenes=True)
        artifact = _artifact(result, panel, recording, record)
    # The final drive was the attack's last rollout (module docstring): the guard holds its counts.
    guard = guard_counts(recording or planner) if result["status"] == "ok" else None
    return crash_record(result, scene.t0_s + scene.horizon_s, guard), artifact


ENTRY = AttackEntry("crash", CrashAttackParams, "selection",
                    "CRASH: a selector picks the adversary in the recorded scene, the traffic model "
                    "generates its future against the planner (closed loop, replanned every k iterations)",
                    run_job=crash_job, scenes=(HIGHWAY, RECORDED))
