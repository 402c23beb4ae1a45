"""Stored attack scenes as a scenario source of `riskmap.evaluation.evaluate` (`adversary evaluate`).

The scenes of a directory `adversary scenes` wrote (its index.json lists them in order; the first
`count`) are the episodes: every planner drives every scene WITHOUT an attack, the scene's own
recorded log with every other vehicle replaying it, in the world the scene's kind builds. The drive
is the judge's unattacked one (`adversary.crash.judge.rollout` with no generated tracks, the
natural drive of `natural_recorded_job` and of the attack's first rollout): highway-env scenes
hand the ego to the planner at t = 0 and drive the whole log (`HighwaySource`), scenes cut from
CommonRoad recordings hand it over at t0 on the recording's lanelets and drive the horizon
(`RecordedSource`). `replay` plays the human's record back, `idm` is IDM/MOBIL (the recordings'
IDM/MOBIL on a recorded scene).

Each drive is measured from the handover (`SceneSource.handover_step`) to its end, in the common
per-episode layout of `riskmap evaluate`: ADE, goal error, jerk and Safety % against the scene's
recorded human over the same steps (`riskmap.evaluation.sources.env.trajectory_metrics`), the
human's own distance beside the ego's; a collision is the judge's (box IoU above
`judge.COLLISION_IOU` with any vehicle, the rollout drives through contacts) and is classified
(`riskmap.sim.records.failures.classify_failure`, no attack to validate); off-road, speed, gap and
plan times are the drive's record. Red-light violations are not counted on these drives ("–").
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from adversary.crash.scene_sweep import read_index
from rasterize.errors import InputError
from rasterize.tracks import Tracks

KIND = "attack_scenes"
MODE = "log"           # the other vehicles always replay the scene's log; no attack is spliced in

# This process's loaded scenes (`load_record` reads the npz and cuts the window once).
_RECORDS: dict = {}


def _record(path: Path):
    from adversary.crash.scenes import load_record

    if path not in _RECORDS:
        _RECORDS[path] = load_record(path)
    return _RECORDS[path]


@dataclass(frozen=True)
class AttackSceneSource:
    """The first `count` (default: every) stored scenes of `scenes_dir`, in index order, each
    driven without an attack by every planner; `seed` seeds the planners."""

    scenes_dir: str
    count: int | None = None
    seed: int = 0

    kind = KIND
    # What these records fill: jerk and the recorded human's distance over the driven steps.
    applies = frozenset({"jerk_mps3", "human_distance_m"})
    # Records are per planner and scene: a resumed run may name more planners or scenes.
    may_change = ("planners", "count")
    differs = "other settings (only --count and --planners may change)"

    def __post_init__(self) -> None:
        object.__setattr__(self, "scenes_dir", str(self.scenes_dir))
        if self.count is not None and self.count < 1:
            raise InputError(f"--count {self.count}: evaluate at least 1 scene")
        self.names()                   # no index, or too few scenes: refused before any work

    def index(self) -> dict:
        return read_index(Path(self.scenes_dir))

    def names(self) -> list[str]:
        """The scenes evaluated, in the index's order."""
        held = self.index()["scenes"]
        if not held:
            raise InputError(f"--scenes {self.scenes_dir} holds no scenes; record some with "
                             "`adversary scenes`")
        if self.count is not None and self.count > len(held):
            raise InputError(f"--scenes {self.scenes_dir} holds {len(held)} scenes, fewer than --count "
                             f"{self.count}; pass a smaller --count or record more with `adversary scenes "
                             "... --resume`")
        return held[:self.count]

    @property
    def recorded(self) -> bool:
        """Scenes cut from CommonRoad recordings (else highway-env episodes)."""
        from adversary.crash.scenes import RECORDED_ENV

        return self.index().get("env_id") == RECORDED_ENV

    @property
    def route_rule(self) -> str:
        # highway-env: the log replay's route (the human's); recordings: the route rule's goal
        return "the route rule" if self.recorded else "the human's route"

    def scenarios(self) -> list[AttackScenario]:
        return [AttackScenario(self, name) for name in self.names()]

    def check(self, planners: tuple[str, ...]) -> None:
        """Every scene loads (a damaged scene file or a recording no longer there fails here) and
        every planner is built, before anything is written."""
        from riskmap.evaluation.sources.base import worker_planner
        from riskmap.registry import display_names

        display_names(planners)      # a bad or repeated name= fails before any work
        for scenario in self.scenarios():
            scenario.record()
        for spec in planners:
            worker_planner(spec, self.seed)

    def settings(self, planners: tuple[str, ...]) -> dict:
        index = self.index()
        return {"scenes": self.scenes_dir, "env_id": index.get("env_id"),
                **({"family": index["family"]} if index.get("family") else {}),
                "count": len(self.names()), "seed": self.seed, "mode": MODE, "planners": list(planners)}

    def title(self) -> str:
        index = self.index()
        what = f"{index.get('family')} recordings" if self.recorded else index.get("env_id")
        return (f"{len(self.names())} attack scene(s) of {what} ({self.scenes_dir}), no attack, mode {MODE}, "
                f"seed {self.seed}, along {self.route_rule}")

    def where(self, row: dict) -> str:
        return f"on scene {row['episode']}"


@dataclass(frozen=True)
class AttackScenario:
    source: AttackSceneSource
    name: str

    @property
    def id(self) -> str:
        return self.name

    @property
    def label(self) -> str:
        return self.name

    @property
    def path(self) -> Path:
        return Path(self.source.scenes_dir) / f"{self.name}.npz"

    def record(self):
        """The stored `SceneRecord` (loaded once per process)."""
        return _record(self.path)

    def prepared(self, out: Path) -> bool:
        return True

    def prepare(self, out: Path) -> None:
        """Nothing: the scene holds its recorded log."""

    def recorded_log(self, out: Path):
        return self.record().log

    def drive(self, spec: str, out: Path) -> dict:
        """The judge's unattacked rollout of this scene with planner SPEC, measured from the
        handover (module docstring); the record to store."""
        from adversary.crash.judge import rollout
        from adversary.crash.scene_source import scene_source
        from riskmap.evaluation.sources.base import worker_planner

        record = self.record()
        planner = worker_planner(spec, self.source.seed)
        no_tracks = np.zeros((0, record.scene.future_steps, 6))
        result = rollout(record, no_tracks, [], planner, spec)
        return drive_record(record, result, spec, self.name, scene_source(record.scene).handover_step(record))

    def row(self, spec: str, record: dict) -> dict:
        from riskmap.evaluation.sources.recordings import recording_label

        return {**record, "planner": spec, "label": recording_label(spec), "episode": self.name, "mode": MODE}


def drive_record(record, result, spec: str, name: str, start: int) -> dict:
    """An unattacked rollout `result` (`judge.Rollout`) of scene `record` as an `EpisodeRecord`
    dict in evaluate's common layout, measured from log step `start` (the handover)."""
    from adversary.crash.judge import first_collision
    from riskmap.evaluation.sources.env import trajectory_metrics
    from riskmap.sim.records.failures import classify_failure, road_rules
    from riskmap.sim.records.metrics import SafetyConfig, path_length_m
    from riskmap.sim.records.record import EpisodeRecord

    log, ego, dt = record.log, result.ego, result.dt_s
    end = record.t0_step + record.stride * record.scene.future_steps + 1      # the rollout's log span
    human = log.states[log.ego_id, start:end][log.valid[log.ego_id, start:end]]
    tracks = result.tracks
    handed_over = Tracks(tracks.states[:, start:], tracks.valid[:, start:], tracks.sizes, tracks.kinds)
    metrics = trajectory_metrics(handed_over, ego, dt, human[:, :2], SafetyConfig())
    others = [a for a in range(tracks.num_agents) if a != ego]
    step, partner, iou = first_collision(tracks, ego, others, start)
    failure = None
    if step is not None:
        failure = classify_failure(tracks, ego, int(partner), step, dt,
                                   **road_rules(record.window.lanes), from_step=start)
    drive = EpisodeRecord.from_dict(result.drive)
    scene = record.scene
    return EpisodeRecord(
        planner=spec, collided=step is not None, off_road=bool(drive.off_road),
        simulated_s=metrics.pop("simulated_s"), distance_m=metrics.pop("distance_m"),
        mean_speed_mps=drive.mean_speed_mps, min_gap_m=drive.min_gap_m, plan_calls=drive.plan_calls,
        plan_ms_median=drive.plan_ms_median, plan_ms_mean=drive.plan_ms_mean, plan_ms_p90=drive.plan_ms_p90,
        implausible_plans=drive.implausible_plans, implausible_plan_first=drive.implausible_plan_first,
        no_solution_plans=drive.no_solution_plans, no_solution_first=drive.no_solution_first,
        extra={"episode": name, "mode": MODE, "failure": failure, **metrics,
               "human_distance_m": path_length_m(human[:, :2]),
               "scene": scene.where, "env_id": scene.env_id, "handover_s": round(start * dt, 3),
               "collision_time_s": None if step is None else round(step * dt, 6),
               "collision_iou": float(iou), "driver": drive.extra.get("driver"),
               "rollout_s": round(result.wall_s, 3)}).as_dict()


__all__ = ["AttackScenario", "AttackSceneSource", "drive_record"]
