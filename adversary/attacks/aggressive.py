"""`aggressive_neighbour`: one neighbour of the ego turns into an aggressive driver aimed at it.

The driver, its parameters and the selection rule are riskmap.sim.drivers.aggressive's (the one scripted
aggressive driver, shared with the guard's scenes); this module makes it a campaign attack.
"""

from __future__ import annotations

from adversary.attacks.base import AttackEntry
from riskmap.sim.drivers.aggressive import AggressiveParams, install_aggressive_neighbour


class AggressiveNeighbour:
    """The attack object of one episode: installs the aggressive neighbour at the start."""

    def __init__(self, params: AggressiveParams, seed: int):
        self.params, self.seed = params, seed
        self.adversary = None

    def start(self, run) -> None:
        self.adversary = install_aggressive_neighbour(run, self.params)

    def step(self, run) -> None:
        pass


ENTRY = AttackEntry("aggressive_neighbour", AggressiveParams, "rule",
                    "one neighbour (STRIVE distance rule or nearest) drives aggressively at the ego: "
                    "short gaps, forced cut-in, brake check",
                    factory=lambda params, seed: AggressiveNeighbour(params, seed))
