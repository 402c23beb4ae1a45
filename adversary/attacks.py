"""The attack interface of stress-test campaigns, and the registry that names attacks.

An attack perturbs one closed-loop episode (riskmap.drive.drive_episode) through two hooks:

    start(run)   once, after the episode is reset and before the ego is handed to the planner:
                 pick an adversary, replace its driver, change the scenario ...
    step(run)    after every simulation step (0.1 s): steer the adversary, log what it needs.

and tells the campaign which vehicle it made the adversary (`adversary`, a highway-env vehicle,
or None when the attack has no single adversary). `run` is a `riskmap.episode.Episode`.
An attack may also define `extra() -> dict` (JSON-ready) to put its own numbers in the record
as `attack_extra`; the report reads `generations` ([{"evaluations": n, "collisions": k}, ...]),
`pareto_front` ([[f1, f2, ...], ...]) and `objective_names` from search attacks.

Each attack is registered under a name with a frozen params dataclass (validated when the
campaign config is read) and a category, which decides where the report shows it:

    baseline     no perturbation (the `natural` episode)
    rule         hand-made adversarial behaviour (e.g. `aggressive_neighbour`)
    selection    learned or distance-based adversary selection + generation (CRASH, STRIVE);
                 `crash` runs on the job's recorded scene, not through the hooks (adversary.crash_attack)
    search       black-box scenario search (NSGA-II, random); these do not use the hooks: the job
                 runs a search and replays its most critical scenario (adversary.search_attack)

Adding an attack is one `register_attack(...)` call in the module that implements it, plus its
import in `_register_builtin`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from adversary.validation import from_mapping
from rasterize.errors import InputError

CATEGORIES = ("baseline", "rule", "selection", "search")


class Attack(Protocol):
    adversary: object | None

    def start(self, run) -> None: ...

    def step(self, run) -> None: ...


@dataclass(frozen=True)
class AttackEntry:
    name: str
    params_type: type                      # frozen dataclass of the attack's parameters
    factory: Callable[[Any, int], Attack]  # (params, seed) -> a fresh Attack for one episode
    category: str
    summary: str                           # one line for the report


_REGISTRY: dict[str, AttackEntry] = {}
_builtin_loaded = False


def register_attack(name: str, params_type: type, factory: Callable[[Any, int], Attack],
                    category: str, summary: str) -> None:
    if category not in CATEGORIES:
        raise ValueError(f"attack category {category!r} is not one of {CATEGORIES}")
    _REGISTRY[name] = AttackEntry(name, params_type, factory, category, summary)


def _register_builtin() -> None:
    # Importing a module registers its attacks.
    from adversary import aggressive, crash_attack, search_attack  # noqa: F401  (aggressive_neighbour; crash; *_search)


def attack_entry(name: str) -> AttackEntry:
    global _builtin_loaded
    if not _builtin_loaded:
        _builtin_loaded = True
        _register_builtin()
    if name not in _REGISTRY:
        raise InputError(f"unknown attack {name!r}; registered attacks: {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]


def attack_names() -> list[str]:
    attack_entry("natural")
    return sorted(_REGISTRY)


def parse_attack_params(name: str, params: dict | None, where: str):
    """The attack's params dataclass from a config mapping (unknown keys are an InputError)."""
    return from_mapping(attack_entry(name).params_type, params or {}, where)


def make_attack(name: str, params, seed: int) -> Attack:
    return attack_entry(name).factory(params, seed)


@dataclass(frozen=True)
class NaturalParams:
    """The natural episode takes no parameters."""


class NaturalEpisode:
    """`natural`: the planner drives the unmodified episode of its seed."""

    adversary = None

    def start(self, run) -> None:
        pass

    def step(self, run) -> None:
        pass


register_attack("natural", NaturalParams, lambda params, seed: NaturalEpisode(), "baseline",
                "the unmodified highway-env episode of the scene seed")
