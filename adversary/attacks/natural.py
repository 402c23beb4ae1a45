"""`natural`: the planner drives the unmodified episode of its seed (category baseline); on a
recorded scenario family, the recorded scene with the ego handed to the planner at t0 (its
hooks perturb nothing, so the recorded job source drives the scene as it is:
adversary.attacks.job_source)."""

from __future__ import annotations

from dataclasses import dataclass

from adversary.attacks.base import HIGHWAY, RECORDED, AttackEntry


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
                    factory=lambda params, seed: NaturalEpisode(), scenes=(HIGHWAY, RECORDED))
