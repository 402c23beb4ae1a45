"""The attack interface of stress-test campaigns: what an attack is and how a job runs it.

An attack perturbs one closed-loop episode (riskmap.sim.worlds.highway_drive.drive_episode) through two hooks:

    start(run)   once, after the episode is reset and before the ego is handed to the planner:
                 pick an adversary, replace its driver, change the scenario ...
    step(run)    after every simulation step (0.1 s): steer the adversary, log what it needs.

and tells the campaign which vehicle it made the adversary (`adversary`, a highway-env vehicle,
or None when the attack has no single adversary). `run` is a `riskmap.sim.worlds.episode.Episode`.
An attack may also define `extra() -> dict` (JSON-ready) to put its own numbers in the record
as `attack_extra`; the report reads `generations` ([{"evaluations": n, "collisions": k}, ...]),
`pareto_front` ([[f1, f2, ...], ...]) and `objective_names` from search attacks.

Each attack is registered under a name with a frozen params dataclass (validated when the
campaign config is read) and a category, which decides where the report shows it:

    baseline     no perturbation (the `natural` episode)
    rule         hand-made adversarial behaviour (e.g. `aggressive_neighbour`)
    selection    learned or distance-based adversary selection + generation (CRASH, STRIVE);
                 `crash` runs on the job's recorded scene, not through the hooks (adversary.attacks.crash)
    search       black-box scenario search (NSGA-II, random); these do not use the hooks: the job
                 runs a search and replays its most critical scenario (adversary.attacks.search)

An attack module defines its `AttackEntry` (or several, `ENTRIES`) and imports only this module;
`adversary.attacks.registry` imports the attack modules (one way) and answers every lookup by name.
An entry either makes episode hooks (`factory`) or runs the whole job itself (`run_job`: CRASH on
the recorded scene, a search then the replay of its most critical scenario), and says which kinds
of job scene it runs against (`scenes`): `HIGHWAY`, a highway-env seed's episode, and `RECORDED`,
a scene cut from a CommonRoad recording (adversary.attacks.recorded). The job's scene source
(adversary.attacks.job_source) runs the entry against the job's scene: `run_job` whatever the
kind; hooks drive a highway-env episode, and on a recorded scene only a baseline's hooks, which
perturb nothing, stand for the scene's unperturbed drive. By default an attack runs on highway-env
families only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

CATEGORIES = ("baseline", "rule", "selection", "search")
# The kinds of job scene (adversary.attacks.job_source): a highway-env seed's episode, a recorded scene.
HIGHWAY, RECORDED = "highway", "recorded"


class Attack(Protocol):
    adversary: object | None

    def start(self, run) -> None: ...

    def step(self, run) -> None: ...


# run_job(job) -> (record fields, artifact npz bytes or None); `job` is a campaign job
# (adversary.campaign.job.Job): planner SPEC and seed, scene, attack params, budget, safety.
JobRunner = Callable[[Any], tuple[dict, bytes | None]]


@dataclass(frozen=True)
class AttackEntry:
    name: str
    params_type: type                      # frozen dataclass of the attack's parameters
    category: str
    summary: str                           # one line for the report
    factory: Callable[[Any, int], Attack] | None = None   # (params, seed) -> hooks for one episode
    run_job: JobRunner | None = None       # runs a whole job instead of hooks
    # The kinds of job scene it runs against; a campaign refuses it on the families of any other
    # (with RECORDED, the job's `scene` is a RecordedScene).
    scenes: tuple[str, ...] = (HIGHWAY,)

    def __post_init__(self) -> None:
        if self.category not in CATEGORIES:
            raise ValueError(f"attack category {self.category!r} is not one of {CATEGORIES}")
        if (self.factory is None) == (self.run_job is None):
            raise ValueError(f"attack {self.name!r} needs exactly one of factory (episode hooks) or run_job")
        if not self.scenes or set(self.scenes) - {HIGHWAY, RECORDED}:
            raise ValueError(f"attack {self.name!r}: scenes {self.scenes} must name {HIGHWAY!r} and/or {RECORDED!r}")
        # Hooks steer highway-env vehicles; a recorded scene has none, so there they can only
        # stand for the unperturbed drive, which is what a baseline's hooks do.
        if RECORDED in self.scenes and self.factory is not None and self.category != "baseline":
            raise ValueError(f"attack {self.name!r}: episode hooks need a highway-env world; give it run_job "
                             f"to run on {RECORDED} scenes")
