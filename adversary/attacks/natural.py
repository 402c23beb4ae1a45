"""`natural`: the planner drives the unmodified episode of its seed (category baseline); on a
recorded scenario family, the recorded scene with the ego handed to the planner at t0
(adversary.attacks.recorded.natural_recorded_job)."""

from __future__ import annotations

from dataclasses import dataclass

from adversary.attacks.base import AttackEntry
from adversary.attacks.recorded import natural_recorded_job


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
                    "the unmodified episode: highway-env's of the scene seed, or the recorded scene "
                    "with the ego handed to the planner at t0",
                    factory=lambda params, seed: NaturalEpisode(), run_recorded=natural_recorded_job)
