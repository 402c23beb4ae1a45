"""`riskmap check-planner SPEC`: drive a planner on a few scenes of each family and say, one line
each, where it breaks the planner contract (docs/guide/your-own-planner.md, "The planner
contract").

The planner drives short closed-loop episodes through the one rollout loop. Every plan it makes is
checked (`riskmap.sim.loop.plan_checks.plan_problems`, the checks the loop itself counts in every
command); a plan that breaks the contract (or a call that raises) is recorded and replaced by a
constant-velocity plan so that the episode, and the check, go on. No solution (`NoSolution`) is
within the contract: counted apart (`Findings.no_solution`), and the loop brakes as it always does.
What the planner declares (`PlannerTraits`, e.g. `attach`) it declares through the checking
wrapper too. Then a few of the scenes it saw are planned again by two fresh planners of the same
SPEC and seed (determinism), and the time per call is compared with the replan period.
"""

from __future__ import annotations

import re
import time
from collections import Counter
from dataclasses import dataclass, field, fields

import numpy as np

from rasterize.timebase import REPLAN_HZ
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS, NoSolution, Plan, PlannerTraits
from riskmap.sim.loop.plan_checks import plan_problems

FAMILY_ENVS = ("highway-v0", "merge-v0", "roundabout-v0", "intersection-v0")
REPLAN_PERIOD_S = 1 / REPLAN_HZ   # the rollout replans at 2 Hz (0.5 s)
_TRAITS = frozenset(f.name for f in fields(PlannerTraits))


@dataclass(frozen=True)
class CheckConfig:
    envs: tuple[str, ...] = FAMILY_ENVS
    episodes: int = 1             # per family
    episode_s: float = 8.0        # seconds driven per episode
    seed: int = 0
    determinism_scenes: int = 3   # scenes planned again by fresh planners
    # CommonRoad recordings (files or folders) to drive instead of the highway-env families: the
    # first `episodes` recorded vehicles of each file, handed to the planner as in
    # `evaluate --commonroad` (log mode, the route rule's goal), each to the end of its record.
    recordings: tuple[str, ...] = ()


@dataclass
class Findings:
    """Breaches by kind (the message with its numbers blanked): count, first message and where."""

    counts: Counter = field(default_factory=Counter)
    first: dict = field(default_factory=dict)
    plans: int = 0
    times_s: list = field(default_factory=list)
    # replans without a plan (`NoSolution`, or a `cr:` planner's missing trajectory): within the
    # contract, so not a breach; the loop brakes as in every command. Count and the first one.
    no_solution: int = 0
    no_solution_first: str | None = None

    def add(self, message: str, where: str) -> None:
        kind = re.sub(r"\d+(\.\d+)?", "#", re.sub(r"0x[0-9a-fA-F]+", "0x#", message))
        self.counts[kind] += 1
        self.first.setdefault(kind, (message, where))

    def lines(self) -> list[str]:
        return [f"{self.first[kind][0]} ({count}x, first on {self.first[kind][1]})"
                for kind, count in self.counts.items()]


def _cv(scene) -> Plan:
    speed = float(scene.ego_state()[4])
    x = speed * PLAN_DT_S * np.arange(1, PLAN_STEPS + 1)
    return Plan(np.stack([x, np.zeros(PLAN_STEPS)], axis=1))


class _Checking:
    """Wraps the planner under test: checks every plan, never lets a bad one reach the loop."""

    def __init__(self, planner, findings: Findings, env_id: str):
        self.planner, self.findings, self.env_id = planner, findings, env_id
        self.scenes: list = []

    def __getattr__(self, name: str):
        # What the planner declares (`PlannerTraits`: `attach`, `route_settings`, ...) it declares
        # through the wrapper too, so that it drives as in every other command: e.g. a `cr:`
        # planner is given the world (`attach`) and so the recording's own lanelet network.
        if name in _TRAITS:
            return getattr(self.planner, name)
        raise AttributeError(name)

    def reset(self, scene) -> None:
        try:
            self.planner.reset(scene)
        except Exception as err:  # noqa: BLE001 - what a planner raises is a finding
            self.findings.add(f"reset() raised {type(err).__name__}: {err}", self.env_id)

    def plan(self, scene) -> Plan:
        where = f"{self.env_id} at {scene.time_s:.1f} s"
        self.scenes.append(scene)
        started = time.perf_counter()
        try:
            plan = self.planner.plan(scene)
        except NoSolution as why:
            self.findings.no_solution += 1
            if self.findings.no_solution_first is None:
                self.findings.no_solution_first = f"on {where}: {why or 'no trajectory'}"
            raise                          # the loop counts it and brakes, as in every command
        except Exception as err:  # noqa: BLE001
            self.findings.add(f"plan() raised {type(err).__name__}: {err}", where)
            return _cv(scene)
        self.findings.times_s.append(time.perf_counter() - started)
        self.findings.plans += 1
        problems = plan_problems(plan, float(scene.ego_state()[4]))
        for problem in problems:
            self.findings.add(problem, where)
        return _cv(scene) if problems else plan


def _determinism(spec: str, config: CheckConfig, scenes: list, findings: Findings) -> None:
    from riskmap.registry import make_planner

    if not scenes or config.determinism_scenes < 1:
        return
    picked = scenes[:: max(1, len(scenes) // config.determinism_scenes)][: config.determinism_scenes]
    twins = [make_planner(spec, seed=config.seed) for _ in range(2)]   # asked the same, in step
    for env_id, scene in picked:
        answers = []
        for planner in twins:
            try:
                planner.reset(scene)
                answers.append(np.asarray(planner.plan(scene).waypoints, dtype=np.float64))
            except NoSolution:
                answers.append(np.zeros((0, 2)))      # no plan: the same answer if both say so
            except Exception:  # noqa: BLE001 - already reported while driving
                return
        if answers[0].shape != answers[1].shape or not np.allclose(answers[0], answers[1],
                                                                     atol=1e-6, equal_nan=True):
            findings.add("two planners made with the same SPEC and seed plan the same scene "
                         "differently; seed every random draw from `seed`",
                         f"{env_id} at {scene.time_s:.1f} s")


def _drive_recordings(planner, config: CheckConfig, findings: Findings, scenes: list,
                      progress: bool) -> None:
    """The first `config.episodes` recorded vehicles of each recording, driven by the checked
    planner among the others replayed (`riskmap evaluate --commonroad`'s episode)."""
    from riskmap.data.collect_commonroad import (
        CommonRoadCollectConfig,
        scenario_files,
        unique_demonstrators,
    )
    from riskmap.sim.worlds.commonroad_replay import replay_commonroad_episode, route_scene_config

    files = scenario_files(list(config.recordings), flag="--commonroad")
    demos, traffics, _ = unique_demonstrators(files, CommonRoadCollectConfig(files=(), smoothing_s=0.0))
    taken: Counter = Counter()
    for demo in demos:
        if taken[demo.path] >= config.episodes:
            continue
        taken[demo.path] += 1
        traffic = traffics[demo.path]
        name = f"{traffic.name} vehicle {int(traffic.ids[demo.agent])}"
        checking = _Checking(planner, findings, name)
        # what the planner sees is the planner's own route rule, not the checking wrapper's
        replay_commonroad_episode(traffic, int(traffic.ids[demo.agent]), checking,
                                  scene_config=route_scene_config(planner))
        scenes.extend((name, scene) for scene in checking.scenes[1:2])
        if progress:
            print(f"  {name}: {findings.plans} plans checked so far", flush=True)


def check_planner(spec: str, config: CheckConfig = CheckConfig(), progress: bool = False,
                  planner=None) -> Findings:
    """Drive `spec` (`planner`, when already made from it with `config.seed`) on
    `config.episodes` short episodes of each family (or recorded vehicles of each of
    `config.recordings`); the breaches found."""
    from riskmap.registry import make_planner
    from riskmap.sim.loop.plan import drives_itself
    from riskmap.sim.worlds.episode import cached_env
    from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

    findings = Findings()
    planner = planner if planner is not None else make_planner(spec, seed=config.seed)
    if drives_itself(planner):
        return findings            # the world's own IDM/MOBIL ego: no plans to check
    scenes = []
    if config.recordings:
        _drive_recordings(planner, config, findings, scenes, progress)
    for env_id in (() if config.recordings else config.envs):
        drive = DriveConfig(env_id=env_id, episodes=config.episodes, seed=config.seed,
                            episode_s=config.episode_s)
        for episode in range(config.episodes):
            checking = _Checking(planner, findings, env_id)
            drive_episode(cached_env(env_id), checking, drive, episode)
            scenes.extend((env_id, scene) for scene in checking.scenes[1:2])   # one per episode
            if progress:
                print(f"  {env_id} episode {episode}: {findings.plans} plans checked so far",
                      flush=True)
    _determinism(spec, config, scenes, findings)
    if findings.times_s:
        median = float(np.median(findings.times_s))
        if median > REPLAN_PERIOD_S:
            findings.add(f"a plan takes {1000 * median:.0f} ms (median); the loop replans every "
                         f"{1000 * REPLAN_PERIOD_S:.0f} ms", "every family")
    return findings
