"""Recorded scenario families of stress-test campaigns: scenes cut from CommonRoad recordings.

A campaign's scenario family is either episodes of a highway-env seed (`env: highway-v0`) or the
first N scenes of a recorded sweep (`commonroad: FILES`), the very sweep `adversary scenes
--commonroad` makes (adversary.crash.recorded: files in natural order, one per moment of
traffic, egos by obstacle id, each attacked `t0` s after its first recorded time; vehicles that
cannot be attacked are skipped). Jobs on a recorded family carry their scene (`RecordedScene`)
and name the family by the env id `commonroad:<family>` (`recorded_env_id`), e.g.
`commonroad:us101`, so that reports group by family and job ids stay readable.

Only attacks whose entry names `RECORDED` among its `scenes` (adversary.attacks.base) run on
recorded families: `natural` (`natural_recorded_job` below, run by the recorded job source,
adversary.attacks.job_source) and `crash` (CRASH on the recorded scene). The others need a
highway-env world and are refused when the campaign config is read.

`natural` on a recorded scene: `adversary.crash.judge.rollout` with no generated tracks (the
others replay the recording, the recorded ego is handed to the planner at t0 and driven for the
scene's horizon, 6 s, at 10 Hz with a plan every 0.5 s: the crash attack's rates, so the
campaign's budget does not apply). The record is the drive's `EpisodeRecord` (collided,
off_road, distance_m, speeds, gaps, plan times, from the one loop) with the fields the episode
monitor (adversary.attacks.monitor) gives a simulated natural job, under the same definitions:
collision type, kinematic value and time of the first contact, the solution check, and Safety %
over the vehicles within `safety.radius_m` at 2 Hz up to the contact. The recorded world drives
on through a contact (as for the crash attack's rollouts), so distance, speed and gap span the
whole horizon; the collision fields are the first contact's. The other vehicles follow their
record, which is never counted off the road (the CRASH judge's rule), so `other_off_road` is
False. A guarded planner's counts (guard_frames, ...) are its guard's in the drive; `guard:idm`
does not drive a recording (the recordings' IDM/MOBIL does), so its guard counts 0 frames.
"""

from __future__ import annotations

import glob
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from rasterize.config import FAMILY_EXTENTS, RasterConfig, family_of_env
from rasterize.errors import InputError

RECORDED_ENV_PREFIX = "commonroad:"
# Raster extents the report draws recorded families with: the urban one (riskmap's recorded
# families) for the Lankershim arterial, highway-env's highway one otherwise.
URBAN_FAMILIES = ("lankershim",)
URBAN_EXTENT_FAMILY = "urban"


def recorded_env_id(family: str) -> str:
    """The env id of a recorded family's jobs, e.g. `commonroad:us101`."""
    return f"{RECORDED_ENV_PREFIX}{family}"


def recorded_family_of(env_id: str) -> str | None:
    """The traffic-model family of a recorded env id; None for a highway-env id."""
    return env_id[len(RECORDED_ENV_PREFIX):] if env_id.startswith(RECORDED_ENV_PREFIX) else None


def job_family(env_id: str) -> str:
    """The scenario family of a job's env id: highway-env's (`family_of_env`) or the recording's."""
    return recorded_family_of(env_id) or family_of_env(env_id)


def job_raster(env_id: str, rows: int = 200, cols: int = 200) -> RasterConfig:
    """The raster the report draws a job's scenes with."""
    family = recorded_family_of(env_id)
    if family is None:
        return RasterConfig(FAMILY_EXTENTS[family_of_env(env_id)], rows, cols)
    if family in URBAN_FAMILIES:
        from riskmap.data.collect_commonroad import RECORDED_FAMILY_EXTENTS

        return RasterConfig(RECORDED_FAMILY_EXTENTS[URBAN_EXTENT_FAMILY], rows, cols)
    return RasterConfig(FAMILY_EXTENTS["highway"], rows, cols)


@dataclass(frozen=True)
class RecordedScene:
    """One scene of a recorded sweep: vehicle `ego_id` of `recording` attacked at `t0_s`
    (recording time). `candidate` is its index among the sweep's candidates, the `episode` of its
    `AttackScene` (as `adversary scenes --commonroad` numbers it); `family` its traffic-model family."""

    recording: str
    ego_id: int
    t0_s: float
    candidate: int
    family: str

    def attack_scene(self):
        from adversary.crash.scenes import RECORDED_ENV, AttackScene

        return AttackScene(RECORDED_ENV, 0, self.candidate, self.t0_s, recording=self.recording,
                           ego_id=self.ego_id)

    def describe(self) -> dict:
        """The scene's fields of a job record (the recording by file name)."""
        return {"family": self.family, "recording": Path(self.recording).name, "ego_id": self.ego_id,
                "t0_s": self.t0_s}


# ---- the sweep of a recorded family ---------------------------------------------------------------

_SWEEPS: dict[tuple, tuple[str, tuple[RecordedScene, ...]]] = {}


def _expand(inputs: tuple[str, ...], where: str) -> list[str]:
    """Paths and globs (relative to the working directory) as paths; a glob that matches nothing
    is an InputError."""
    out = []
    for item in inputs:
        if glob.has_magic(item):
            found = sorted(glob.glob(item))
            if not found:
                raise InputError(f"{where}.commonroad: {item} matches no file; point it at your CommonRoad "
                                 "NGSIM scenario files (.xml) or a directory of them")
            out += found
        else:
            out.append(item)
    return out


def _family_of_files(files: list[Path], family: str | None, where: str) -> str:
    """The family of `files` (`family` when given, else from their names), with the name checks
    of `sweep_files` worded for a campaign config."""
    from adversary.crash.recorded import FAMILY_NAME, RECORDED_FAMILIES, recording_family

    for path in files:
        if path.suffix.lower() != ".xml":
            raise InputError(f"{where}.commonroad: {path} is not a CommonRoad .xml scenario; list .xml "
                             "files or directories holding them")
    if family is not None:
        if not FAMILY_NAME.match(family):
            raise InputError(f"{where}.family {family!r}: use a lower-case name (letters, digits, _), "
                             "e.g. us101")
        return family
    for path in files:
        if not any(path.name.startswith(prefix) for prefix, _ in RECORDED_FAMILIES):
            listed = ", ".join(f"{prefix}* -> {known}" for prefix, known in RECORDED_FAMILIES)
            raise InputError(f"{where}: cannot tell the family of {path.name} from its name ({listed}); "
                             "add family: NAME to the scenario family")
    families = sorted({recording_family(p) for p in files})
    if len(families) > 1:
        raise InputError(f"{where}.commonroad mixes recordings of several families ({', '.join(families)}); "
                         "give each site its own scenario family")
    return families[0]


_FILES: dict[tuple, tuple[tuple[Path, ...], str]] = {}


def recorded_files(inputs: tuple[str, ...], family: str | None, where: str) -> tuple[tuple[Path, ...], str]:
    """(the CommonRoad files `inputs` name, their family), without parsing them; an InputError
    naming `where` for missing or unusable files."""
    key = (tuple(inputs), family, os.getcwd())
    if key not in _FILES:
        from riskmap.data.collect_commonroad import scenario_files

        files = scenario_files(_expand(inputs, where), flag=f"{where}.commonroad")
        _FILES[key] = (tuple(files), _family_of_files(files, family, where))
    return _FILES[key]


def recorded_sweep(inputs: tuple[str, ...], family: str | None, t0_after_s: float, episodes: int,
                   where: str) -> tuple[str, tuple[RecordedScene, ...]]:
    """(family, the first `episodes` scenes) of the sweep over `inputs` (module docstring);
    an InputError naming `where` when files are missing or there are too few scenes. Computed
    once per process and arguments (parsing a recording takes a second or two)."""
    key = (tuple(inputs), family, float(t0_after_s), int(episodes), os.getcwd())
    if key in _SWEEPS:
        return _SWEEPS[key]
    from adversary.crash.recorded import sweep_files, sweep_scenes

    files, name = recorded_files(inputs, family, where)
    try:
        kept, name, _ = sweep_files(list(files), name)
    except InputError as error:
        raise InputError(str(error).replace("--commonroad", f"{where}.commonroad", 1)) from None
    scenes = []
    for index, path, ego_id, t0_s, record, _ in sweep_scenes(kept, name, t0_after_s):
        if record is not None:
            scenes.append(RecordedScene(str(path), int(ego_id), float(t0_s), int(index), name))
            if len(scenes) == episodes:
                break
    if len(scenes) < episodes:
        what = "no scene" if not scenes else f"only {len(scenes)} scene(s)"
        raise InputError(f"{where}: the {len(kept)} recording(s) hold {what} that can be attacked "
                         f"(t0 {t0_after_s:g} s after each vehicle's first recorded time), fewer than "
                         f"episodes: {episodes}; lower episodes or add recordings")
    _SWEEPS[key] = (name, tuple(scenes))
    return _SWEEPS[key]


def scene_record(scene: RecordedScene):
    """The job's `SceneRecord`, exactly as the sweep recorded it."""
    from adversary.crash.recorded import record_recorded_scene

    return record_recorded_scene(scene.attack_scene(), family=scene.family)


# ---- the natural job on a recorded scene ----------------------------------------------------------

def _vehicle(state: np.ndarray, size: np.ndarray) -> SimpleNamespace:
    """A world state [6] and box as the highway-env vehicle the campaign metrics read."""
    heading = state[2:4] / max(float(np.linalg.norm(state[2:4])), 1e-12)
    return SimpleNamespace(position=state[:2], heading=math.atan2(heading[1], heading[0]),
                           velocity=state[4] * heading, LENGTH=float(size[0]), WIDTH=float(size[1]))


def _encounters(result, contact_step: int | None, safety, every: int) -> tuple[int, int]:
    """(dangerous encounters, encounters) at every `every`-th step after t0 before the first
    contact, as `EpisodeMonitor` counts them."""
    from riskmap.sim.records.metrics import closing_dangerous_encounters

    ego, s, v = result.ego, result.states, result.valid
    last = int(np.flatnonzero(v[ego])[-1])
    end = last if contact_step is None else contact_step - 1
    dangerous = total = 0
    for k in range(result.t0_step + every, end + 1, every):
        if not v[ego, k]:
            continue
        others = [_vehicle(s[a, k], result.sizes[a]) for a in np.flatnonzero(v[:, k]) if a != ego]
        d, n = closing_dangerous_encounters(_vehicle(s[ego, k], result.sizes[ego]), others, safety)
        dangerous += d
        total += n
    return dangerous, total


def natural_record(result, scene: RecordedScene, safety, driver: str | None = None,
                   guard: dict | None = None, lanes=()) -> dict:
    """The job record fields of a natural drive on a recorded scene (module docstring); `driver`:
    the name of what drove the ego (default: the drive's own); `guard`: the guard's counts
    (adversary.attacks.episode.guard_counts; default: no guard); `lanes`: the scene's lanes, on
    which the failure classification may change lanes (none: it only brakes or speeds up)."""
    from adversary.attacks.episode import GUARD_FIELDS, job_fields
    from adversary.crash.recorded import recording_traffic
    from riskmap.sim.records.alternatives import ego_only_solution
    from riskmap.sim.records.metrics import coarse_collision_type, safety_pct
    from riskmap.sim.records.record import EpisodeRecord

    drive = EpisodeRecord.from_dict(result.drive)
    contact = drive.extra.get("contact")
    collision = {"collision_type": None, "collision_time_s": None, "kinematic_mps": None}
    solution = step = failure = None
    if contact is not None:
        step = round(contact["time_s"] / result.dt_s)
        partner = recording_traffic(scene.recording).index_of(contact["other_id"])
        ego_v = _vehicle(result.states[result.ego, step], result.sizes[result.ego])
        other_v = _vehicle(result.states[partner, step], result.sizes[partner])
        collision = {"collision_type": coarse_collision_type(ego_v, other_v),
                     "collision_time_s": float(contact["time_s"]),
                     "kinematic_mps": float(np.linalg.norm(ego_v.velocity - other_v.velocity))}
        solution = ego_only_solution(result.tracks, result.ego, step, result.dt_s)
        failure = classify_recorded_collision(result, partner, step, lanes)
    dangerous, encounters = _encounters(result, step, safety, max(1, round(0.5 / result.dt_s)))
    return job_fields(replace(drive, planner="", extra={
        "has_adversary": False, "collided_with_adversary": False, **collision,
        "adversary_off_road": None, "other_off_road": False,
        "encounters": encounters, "dangerous_encounters": dangerous,
        "safety_pct": safety_pct(dangerous, encounters),
        "solution_found": None if solution is None else bool(solution),
        "failure": failure,
        "env_seed": None,
        **(guard or dict.fromkeys(GUARD_FIELDS)),
        "attack_extra": {"contact": contact, "driver": driver or drive.extra.get("driver")},
    }))


def classify_recorded_collision(result, partner: int, step: int, lanes=()) -> dict:
    """`riskmap.sim.records.failures.classify_failure` of a natural drive's contact on a recording (no
    attack to validate); with `lanes`, lane changes that keep the box on them count too."""
    from riskmap.sim.records.failures import classify_failure, road_rules

    return classify_failure(result.tracks, result.ego, partner, step, result.dt_s, **road_rules(lanes),
                            from_step=result.t0_step)


def natural_recorded_job(job) -> tuple[dict, bytes]:
    """(record fields, artifact) of a `natural` job on a recorded scene (module docstring)."""
    from adversary.attacks.episode import RecordingPlanner, clear_guard, guard_counts, npz_bytes, scene_arrays
    from adversary.crash.judge import rollout
    from riskmap.registry import cached_planner
    from riskmap.sim.loop.plan import drives_itself

    record = scene_record(job.scene)
    planner = cached_planner(job.planner, job.planner_seed)
    recording = None if drives_itself(planner) else RecordingPlanner(planner)
    empty = np.zeros((0, record.scene.future_steps, 6))
    # `guard:idm` does not drive a recording (the recordings' IDM does): its guard then counts 0 frames.
    clear_guard(planner)
    result = rollout(record, empty, [], recording or planner, job.planner, keep_scene=True)
    artifact = npz_bytes(scene_arrays(result.final_scene, None, recording))
    # The drive names the planner it was handed; with the recording wrapper, name the planner.
    driver = None if recording is None else type(planner).__name__
    return natural_record(result, job.scene, job.safety, driver, guard_counts(recording or planner),
                          record.window.lanes), artifact
