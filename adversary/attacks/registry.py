"""The registry of campaign attacks: every attack by name (adversary.attacks.base).

It imports the attack modules, one way, and owns every lookup; a new attack module is one more
import in `_BUILTIN_MODULES`. `register_attack` adds one at run time (tests, experiments).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from adversary.attacks import aggressive, crash, natural, search
from adversary.attacks.base import Attack, AttackEntry
from adversary.attacks.natural import NaturalEpisode, NaturalParams
from rasterize.errors import InputError
from riskmap.infra.config_mapping import from_mapping

__all__ = ["NaturalEpisode", "NaturalParams", "attack_entry", "attack_names", "make_attack",
           "parse_attack_params", "register_attack"]

_BUILTIN_MODULES = (natural, aggressive, crash, search)
_REGISTRY: dict[str, AttackEntry] = {
    entry.name: entry for module in _BUILTIN_MODULES
    for entry in getattr(module, "ENTRIES", (getattr(module, "ENTRY", None),)) if entry is not None}


def register_attack(name: str, params_type: type, factory: Callable[[Any, int], Attack],
                    category: str, summary: str) -> None:
    """Add an episode-hook attack under `name` (replacing one of that name)."""
    _REGISTRY[name] = AttackEntry(name, params_type, category, summary, factory=factory)


def attack_entry(name: str) -> AttackEntry:
    if name not in _REGISTRY:
        raise InputError(f"unknown attack {name!r}; use one of the registered attacks: "
                         f"{', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]


def attack_names() -> list[str]:
    return sorted(_REGISTRY)


def parse_attack_params(name: str, params: dict | None, where: str):
    """The attack's params dataclass from a config mapping (unknown keys are an InputError)."""
    return from_mapping(attack_entry(name).params_type, params or {}, where)


def make_attack(name: str, params, seed: int) -> Attack:
    """Fresh episode hooks of attack `name` for one episode."""
    entry = attack_entry(name)
    if entry.factory is None:
        raise InputError(f"attack {name!r} runs whole jobs, not episode hooks")
    return entry.factory(params, seed)
