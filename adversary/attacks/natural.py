"""`natural`: the planner drives the unmodified episode of its seed (category baseline)."""

from __future__ import annotations

from dataclasses import dataclass

from adversary.attacks.base import AttackEntry


@dataclass(frozen=True)
class NaturalParams:
    """The natural episode takes no parameters."""


class NaturalEpisode:
    adversary = None

    def start(self, run) -> None:
        pass

    def step(self, run) -> None:
        pass


ENTRY = AttackEntry("natural", NaturalParams, "baseline",
                    "the unmodified highway-env episode of the scene seed",
                    factory=lambda params, seed: NaturalEpisode())
