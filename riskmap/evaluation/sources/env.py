"""highway-env seeds as a scenario source (`riskmap evaluate --env`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from rasterize.config import family_of_env
from rasterize.errors import InputError
from rasterize.timebase import CONTROL_HZ, REPLAN_HZ
from rasterize.tracks import Tracks
from riskmap.evaluation.sources.base import planner_label, worker_planner
from riskmap.registry import display_names
from riskmap.sim.loop.rollout import check_replan_hz
from riskmap.sim.records.metrics import (
    SafetyConfig,
    ade_m,
    dangerous_encounters,
    goal_error_m,
    mean_jerk_mps3,
    path_length_m,
    safety_pct,
)
from riskmap.sim.worlds.episode import FAMILY_SETUPS, cached_env

MODES = ("log", "reactive")


@dataclass(frozen=True)
class EnvSource:
    """Episodes 0..episodes-1 of `env_id` under `seed`: the IDM/MOBIL human is driven and recorded
    first (OUT/logs), then every planner drives its ego from the human's start along the human's
    route, among traffic replaying the log (`log`) or reacting (`reactive`). `idm` is the log
    itself; `replay` plays it back through the harness (log mode only). Times in s, rates in Hz."""

    env_id: str
    episodes: int
    seed: int = 0
    mode: str = "log"
    control_hz: int = CONTROL_HZ
    replan_hz: int = REPLAN_HZ
    episode_s: float | None = None        # default: the family's episode length
    safety: SafetyConfig = field(default_factory=SafetyConfig)

    kind = "env"
    route_rule = "the human's route"
    applies = frozenset({"jerk_mps3"})
    may_change = ("config.episodes", "config.planners")
    differs = "other settings (only --episodes and --planners may change)"

    def __post_init__(self) -> None:
        family = family_of_env(self.env_id)
        if self.mode not in MODES:
            raise InputError(f"--mode {self.mode!r} is unknown; use log or reactive")
        if self.episodes < 1:
            raise InputError("--episodes must be at least 1")
        check_replan_hz(self.replan_hz, self.control_hz)
        if self.episode_s is None:
            object.__setattr__(self, "episode_s", FAMILY_SETUPS[family].episode_s)
        if not 0 < self.episode_s < float("inf"):
            raise InputError(f"--episode-s must be positive seconds, got {self.episode_s}")

    def check(self, planners: tuple[str, ...]) -> None:
        """InputError for planners this source cannot run; each is built, so a bad SPEC fails
        before any work."""
        display_names(planners)      # a bad or repeated name= fails before any work
        if self.mode == "reactive" and "replay" in planners:
            raise InputError("planner `replay` plays back the record, which reactive traffic no longer "
                             "follows; use it with --mode log only")
        for spec in planners:
            if spec != "idm":          # the human is the log, not a planner
                worker_planner(spec, self.seed)

    def scenarios(self) -> list[EnvScenario]:
        return [EnvScenario(self, e) for e in range(self.episodes)]

    def settings(self, planners: tuple[str, ...]) -> dict:
        # the layout of the runs before sources (EvalConfig's fields), so their run.json resumes
        config = asdict(self)
        return {"config": {"env_id": self.env_id, "planners": list(planners),
                           **{k: v for k, v in config.items() if k != "env_id"}}}

    def title(self) -> str:
        return f"{self.env_id}, mode {self.mode}, seed {self.seed}, along {self.route_rule}"

    def where(self, row: dict) -> str:
        return f"in episode {row['episode']}"


@dataclass(frozen=True)
class EnvScenario:
    source: EnvSource
    episode: int

    @property
    def id(self) -> str:
        return f"episode_{self.episode:06d}"

    @property
    def label(self) -> int:
        return self.episode

    def _log_path(self, out: Path) -> Path:
        return Path(out) / "logs" / f"{self.id}.npz"

    def prepared(self, out: Path) -> bool:
        return self._log_path(out).exists()

    def prepare(self, out: Path) -> None:
        """Record the human's episode unless it is on disk."""
        from riskmap.sim.worlds.log_replay import record_human_episode

        if self.prepared(out):
            return
        s = self.source
        log = record_human_episode(cached_env(s.env_id, s.control_hz), s.env_id, s.seed, self.episode,
                                   s.control_hz, s.episode_s)
        log.save(self._log_path(out))

    def recorded_log(self, out: Path):
        from riskmap.sim.worlds.log_replay import HumanLog

        return HumanLog.load(self._log_path(out))

    def drive(self, spec: str, out: Path) -> dict:
        """Drive (or, for `idm`, read) this episode; returns its record of metrics."""
        from riskmap.sim.loop.plan import traits_of
        from riskmap.sim.records.failures import classify_failure, classify_run, first_contact
        from riskmap.sim.worlds.episode import Episode
        from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode
        from riskmap.sim.worlds.log_replay import LogReplayEpisode

        s = self.source
        log = self.recorded_log(out)
        human_xy = log.ego_xy()
        base = {"label": planner_label(spec), "episode": self.episode, "mode": s.mode}
        if spec == "idm":
            tracks = log.tracks()
            metrics = trajectory_metrics(tracks, log.ego_id, log.dt_s, human_xy, s.safety)
            contact = first_contact(tracks, log.ego_id) if log.crashed else None
            base["failure"] = None if contact is None else classify_failure(
                tracks, log.ego_id, contact[1], contact[0], log.dt_s)
            return _table_record(spec, base, metrics, log.crashed, log.off_road, None)
        env = cached_env(s.env_id, s.control_hz)
        planner = worker_planner(spec, s.seed)
        traits = traits_of(planner)
        replay = bool(traits.requires_log)
        if replay:
            traits.set_log(log)
        if s.mode == "log":
            run = LogReplayEpisode(env, s.env_id, s.seed, self.episode, log, s.control_hz, replay_ego=replay)
        else:
            run = Episode(env, s.env_id, s.seed, self.episode, s.control_hz)
        drive_config = DriveConfig(s.env_id, s.episodes, s.seed, s.control_hz, s.replan_hz, s.episode_s)
        record = drive_episode(env, planner, drive_config, self.episode, run=run)
        metrics = trajectory_metrics(run.recorder.tracks(), run.recorder.ego_id, run.dt, human_xy, s.safety)
        base["failure"] = classify_run(run) if record["collided"] else None
        return _table_record(spec, base, metrics, record["collided"], record["off_road"], record)

    def row(self, spec: str, record: dict) -> dict:
        return record                   # written in the common layout already


def _table_record(spec: str, base: dict, metrics: dict, collided: bool, off_road: bool,
                  drive: dict | None) -> dict:
    """One episode as an `EpisodeRecord` dict. Distance and simulated time are the recorded
    states' (the same for the human's log and a driven episode); speed, gap and plan times come
    from the drive (`drive_episode`'s record) and are None for the human, who is not driven."""
    from riskmap.sim.records.record import EpisodeRecord

    metrics = dict(metrics)
    drive = drive or {"mean_speed_mps": None, "min_gap_m": None, "plan_calls": 0,
                      "plan_ms_median": None, "plan_ms_mean": None, "plan_ms_p90": None,
                      "implausible_plans": 0, "implausible_plan_first": None,
                      "no_solution_plans": 0, "no_solution_first": None}
    return EpisodeRecord(
        planner=spec, collided=bool(collided), off_road=bool(off_road),
        simulated_s=metrics.pop("simulated_s"), distance_m=metrics.pop("distance_m"),
        mean_speed_mps=drive["mean_speed_mps"], min_gap_m=drive["min_gap_m"],
        plan_calls=drive["plan_calls"], plan_ms_median=drive["plan_ms_median"],
        plan_ms_mean=drive["plan_ms_mean"], plan_ms_p90=drive["plan_ms_p90"],
        implausible_plans=drive["implausible_plans"], implausible_plan_first=drive["implausible_plan_first"],
        no_solution_plans=drive.get("no_solution_plans", 0), no_solution_first=drive.get("no_solution_first"),
        extra={**base, **metrics}).as_dict()

def trajectory_metrics(tracks: Tracks, ego_id: int, dt_s: float, human_xy: np.ndarray,
                       safety: SafetyConfig) -> dict:
    """Metrics of one driven episode from its record's `tracks`."""
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    ego = states[ego_id][valid[ego_id]]
    others = np.delete(np.arange(states.shape[0]), ego_id)
    dangerous, encounters = dangerous_encounters(ego, sizes[ego_id], states[others], valid[others],
                                                 sizes[others], safety)
    return {"ade_m": ade_m(ego[:, :2], human_xy), "goal_error_m": goal_error_m(ego[:, :2], human_xy),
            "distance_m": path_length_m(ego[:, :2]), "jerk_mps3": mean_jerk_mps3(ego[:, :2], dt_s),
            "dangerous": dangerous, "encounters": encounters,
            "safety_pct": safety_pct(dangerous, encounters),
            "simulated_s": round((len(ego) - 1) * dt_s, 3)}
