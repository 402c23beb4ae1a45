"""The recorded vehicles of CommonRoad files as a scenario source (`riskmap evaluate --commonroad`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from rasterize.timebase import REPLAN_HZ
from riskmap.evaluation.sources.base import planner_label, worker_planner
from riskmap.registry import display_names

_TRAFFIC: dict = {}


def recorded_traffic(path: Path):
    """This process's parsed recording of `path` (parsing a file takes about a second)."""
    from rasterize.commonroad.reader import load_scenario
    from rasterize.commonroad.tracks import RecordedTraffic

    if path not in _TRAFFIC:
        _TRAFFIC[path] = RecordedTraffic(load_scenario(path), path.stem)
    return _TRAFFIC[path]


@dataclass(frozen=True)
class RecordingSource:
    """Every vehicle that `riskmap collect --from-commonroad` makes a demonstrator (2 s of history
    and 6 s of future; once, however many files of its traffic configuration hold it) is one
    episode: handed over to the planner 2 s into its record and driven to its end among the other
    recorded vehicles (`riskmap.sim.worlds.commonroad_replay`): by time in `log` mode, along their paths
    braking for the ego in `reactive` mode, towards `goal` (the route rule, or the human's own
    end). `replay` is the recording tracked by the controller, `idm` IDM + MOBIL along the
    vehicle's lanelets (`riskmap.sim.drivers.recorded_idm`). `limit`: only that many vehicles, drawn with
    `seed` (kept in file order), the same for every planner; `goal_variance` (cells²) overrides
    risk-map planners' planning-time goal variance."""

    recordings: tuple[str, ...]
    seed: int = 0
    goal: str = "route"
    mode: str = "log"
    goal_variance: float | None = None
    replan_hz: int = REPLAN_HZ
    limit: int | None = None

    kind = "commonroad"
    applies = frozenset({"human_distance_m", "red_light_violations"})
    # Records are per planner and episode, so a resumed run may name more (or fewer) planners.
    may_change = ("planners",)
    differs = "other settings"

    def __post_init__(self) -> None:
        object.__setattr__(self, "recordings", tuple(str(r) for r in self.recordings))
        self.replay_config()           # validates goal, mode and replan_hz before any work

    @property
    def route_rule(self) -> str:
        return self.goal

    def replay_config(self):
        from riskmap.sim.worlds.commonroad_replay import ReplayConfig

        return ReplayConfig(goal=self.goal, mode=self.mode, replan_hz=self.replan_hz)

    def files(self) -> list[Path]:
        from riskmap.data.collect_commonroad import scenario_files

        return scenario_files(list(self.recordings), flag="--commonroad")

    def scenarios(self) -> list[RecordedScenario]:
        """The recorded vehicles in file order (`limit` of them drawn with `seed`); parses every
        file (kept for this process's episodes)."""
        from riskmap.data.collect_commonroad import (
            CommonRoadCollectConfig,
            no_demonstrators_message,
            unique_demonstrators,
        )

        files = self.files()
        # The recording as it is (no smoothing); a vehicle recorded in several files of one traffic
        # configuration is one episode (the first file's).
        config = CommonRoadCollectConfig(files=(), smoothing_s=0.0)
        demos, traffics, skipped = unique_demonstrators(files, config)
        if not demos:
            raise InputError(f"--commonroad: {no_demonstrators_message(files, config, skipped)}; "
                             "nothing to evaluate")
        _TRAFFIC.update(traffics)
        episodes = [RecordedScenario(self, d.path, traffics[d.path].name, int(traffics[d.path].ids[d.agent]))
                    for d in demos]
        if self.limit is not None:
            if self.limit < 1:
                raise InputError(f"--max-episodes {self.limit}: give at least 1 recorded vehicle")
            if self.limit < len(episodes):
                keep = np.sort(np.random.default_rng(self.seed).choice(len(episodes), self.limit, replace=False))
                episodes = [episodes[i] for i in keep]
        return episodes

    def check(self, planners: tuple[str, ...]) -> None:
        display_names(planners)       # a bad or repeated name= fails here too
        for spec in planners:           # a bad SPEC fails before anything is written
            if spec not in ("replay", "idm"):       # these two are made per recorded vehicle
                worker_planner(spec, self.seed, self.goal_variance)

    def settings(self, planners: tuple[str, ...]) -> dict:
        # the layout of the runs before sources, so their run.json resumes
        return {"recordings": [str(p) for p in self.files()], "planners": list(planners), "seed": self.seed,
                "goal": self.goal, "mode": self.mode,
                **({"goal_variance": self.goal_variance} if self.goal_variance is not None else {}),
                **({"max_episodes": self.limit} if self.limit is not None else {}),
                # named only when not the default, so run.json of runs from before it still resume
                **({"replan_hz": self.replan_hz} if self.replan_hz != REPLAN_HZ else {})}

    def title(self) -> str:
        return f"{len(self.files())} recording(s), mode {self.mode}, seed {self.seed}, goal {self.route_rule}"

    def where(self, row: dict) -> str:
        return f"on {row['scenario']} vehicle {row['ego_id']}"


@dataclass(frozen=True)
class RecordedScenario:
    source: RecordingSource
    path: Path
    scenario: str
    vehicle: int

    @property
    def id(self) -> str:
        return f"{self.scenario}_{self.vehicle}"

    @property
    def label(self) -> str:
        return self.id

    def prepared(self, out: Path) -> bool:
        return True

    def prepare(self, out: Path) -> None:
        """Nothing: the recording is the log."""

    def recorded_log(self, out: Path):
        return recorded_traffic(self.path)

    def _planner(self, spec: str):
        """`replay` and `idm` are tied to their recording; any other SPEC is made once per process
        and reused (each episode resets it, so results do not depend on order)."""
        from riskmap.sim.drivers.recorded_idm import RecordedRouteIdmPlanner
        from riskmap.sim.worlds.commonroad_replay import RecordedFuturePlanner

        traffic = recorded_traffic(self.path)
        if spec == "replay":
            return RecordedFuturePlanner(traffic, self.vehicle)
        if spec == "idm":
            return RecordedRouteIdmPlanner(traffic, self.vehicle)
        return worker_planner(spec, self.source.seed, self.source.goal_variance)

    def drive(self, spec: str, out: Path) -> dict:
        from riskmap.sim.worlds.commonroad_replay import replay_commonroad_episode

        planner = self._planner(spec)
        return replay_commonroad_episode(self.recorded_log(out), self.vehicle, planner,
                                         config=self.source.replay_config())

    def row(self, spec: str, record: dict) -> dict:
        # The stored record names the planner class and keeps the failure in its collision.
        return {**record, "planner": spec, "label": recording_label(spec), "episode": self.id,
                "mode": self.source.mode, "failure": (record.get("collision") or {}).get("failure")}


def recording_label(spec: str) -> str:
    """On recordings `replay` is the human (tracked) and `idm` the rule-based baseline."""
    return {"replay": "Human (replay)", "idm": "IDM"}.get(spec) or planner_label(spec)
