"""Scripted aggressive neighbours: the "adversarial" scenes of the guard's data and evaluation.

No learned adversary is used here: at the start of an episode one neighbour of the ego becomes
the toolkit's one scripted aggressive driver (riskmap.sim.aggressive: STRIVE's distance rule picks
it; it catches up, tailgates, cuts into the ego's lane and brake-checks), with the same parameters
as the campaign attack `aggressive_neighbour`.
"""

from __future__ import annotations

from riskmap.sim.aggressive import AggressiveParams, install_aggressive_neighbour


class AggressorHook:
    """Callable hook for `riskmap.sim.rollout.drive_episode` (`DriveHooks.on_ready`); remembers
    the aggressor it installed.

    It runs after the planner's own hooks, so a guard or planner may already have replaced the
    ego vehicle object; the aggressor follows the ego `run.ego` names at every step.
    """

    def __init__(self, params: AggressiveParams = AggressiveParams()):
        self.params, self.aggressor = params, None

    def __call__(self, run) -> None:
        self.aggressor = install_aggressive_neighbour(run, self.params)
