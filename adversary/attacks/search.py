"""Search attacks of stress-test campaigns: a short black-box scenario search against the planner
under test (adversary.search.run, in process), then the closed-loop episode of the most critical
scenario it found. In a campaign config:

    attacks:
      - {name: nsga2_search, label: nsga2-cut-in, envs: [highway-v0],
         params: {template: cut_in, pop: 6, generations: 3, episode_s: 8.0}}
      - {name: random_search, envs: [highway-v0], params: {template: lead_brakes}}

A template places the ego and one target on an empty highway-v0 road (adversary.search.scenarios), so a
search attack does not use its job's recorded scene: the job's (campaign seed, scene seed,
episode) only seed the search (`search_seed`): every episode of a family is one more independent
search, and every planner starts from the same initial population. The job's record is the replayed episode of the most critical vector
(adversary.search.run.most_critical), so for this attack "collision rate" is the share of searches
that found a failure; `attack_extra` holds the per-generation collisions, the Pareto front and
the best parameters (SearchOutcome.extra). A guarded planner's counts (guard_frames, ...) are the
replay's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adversary.attacks.base import AttackEntry
from adversary.attacks.episode import RecordingPlanner, artifact_of, clear_guard, record_of
from adversary.attacks.monitor import EpisodeMonitor
from adversary.search.scenarios import ENV_ID, TEMPLATES
from riskmap.infra.config_mapping import require
from riskmap.sim.loop.plan import drives_itself

SEARCH_ATTACKS = {"nsga2_search": "nsga2", "random_search": "random"}   # attack -> algorithm
SEARCH_ENV_ID = ENV_ID                 # the only env a template builds its road in


@dataclass(frozen=True)
class SearchAttackParams:
    template: str = "cut_in"           # adversary.search.scenarios name
    pop: int = 6                       # evaluations per generation
    generations: int = 3               # the budget is pop × generations closed-loop episodes
    episode_s: float = 8.0             # simulated seconds per evaluation and of the replay

    def __post_init__(self) -> None:
        require(self.template in TEMPLATES, f"search attack template {self.template!r}: use one of "
                                            f"{', '.join(sorted(TEMPLATES))}")
        require(self.pop >= 2, f"search attack pop must be >= 2, got {self.pop}")
        require(self.generations >= 1, f"search attack generations must be >= 1, got {self.generations}")
        require(self.episode_s > 0, f"search attack episode_s must be positive, got {self.episode_s}")


# The search's seed is also the planner's seed, and the risk-map planner seeds scikit-learn's
# KMeans with seed · 1 000 003 + plan calls, which must stay below 2³²: seeds stay below 4096.
SEARCH_SEEDS = 4096


def search_seed(planner_seed: int, scene_seed: int, episode: int) -> int:
    """The search's seed (pymoo, planner sampling, perception noise) for one job, in
    [0, SEARCH_SEEDS); two jobs share one with probability 1/4096."""
    return int(np.random.SeedSequence([planner_seed, scene_seed, episode]).generate_state(1)[0]
               % SEARCH_SEEDS)


def search_config(attack_name: str, params: SearchAttackParams, planner: str, seed: int):
    """The `adversary search` configuration one job runs (one process: the campaign already
    runs jobs in parallel)."""
    from adversary.search.run import SearchConfig

    return SearchConfig(planner=planner, template=params.template,
                        algorithm=SEARCH_ATTACKS[attack_name], pop=params.pop, gen=params.generations,
                        seed=seed, episode_s=params.episode_s, workers=1)


class ReplayedScenario:
    """The replay of the most critical scenario as the attack the episode monitor observes: the
    template put the ego and its target on an empty road, and the target is the adversary."""

    def __init__(self):
        self.adversary = None

    def start(self, run) -> None:
        self.adversary = next(v for v in run.base.road.vehicles if v is not run.ego)

    def step(self, run) -> None:
        pass


def search_and_replay(job) -> tuple[dict, bytes]:
    """Search scenarios against the job's planner, then replay the most critical one (category
    search; adversary.attacks.search)."""
    from adversary.search.evaluation import run_scenario
    from adversary.search.run import search_in_process
    from adversary.search.scenarios import get_template

    config = search_config(job.attack_name, job.attack_params, job.planner,
                           search_seed(job.planner_seed, job.scene_seed, job.episode))
    outcome = search_in_process(config)
    template = get_template(config.template)
    monitor = EpisodeMonitor(ReplayedScenario(), job.safety, config.evaluation.control_hz)
    recordings, driven = [], []

    def wrap(planner):
        clear_guard(planner)          # the search's evaluations drove it before the replay
        recordings.append(None if drives_itself(planner) else RecordingPlanner(planner))
        driven.append(recordings[0] or planner)
        return driven[0]

    episode, _ = run_scenario(template, np.asarray(outcome.best_x), config.evaluation,
                              on_reset=monitor.start, on_step=monitor.step, wrap_planner=wrap)
    record = record_of(episode, monitor, outcome.extra(template), driven[0])
    return record, artifact_of(monitor, recordings[0], SEARCH_ENV_ID)


ENTRIES = tuple(
    AttackEntry(name, SearchAttackParams, "search",
                f"{'NSGA-II' if algorithm == 'nsga2' else 'random'} search over a template's "
                "parameters; the episode of the most critical scenario found",
                run_job=search_and_replay)
    for name, algorithm in SEARCH_ATTACKS.items())
