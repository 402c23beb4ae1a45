"""Scripted aggressive neighbours: the "adversarial" scenes of the guard's data and evaluation.

No learned adversary is used here: at the start of an episode one neighbour of the ego becomes
the toolkit's one scripted aggressive driver (riskmap.sim.drivers.aggressive: STRIVE's distance rule picks
it; it catches up, tailgates, cuts into the ego's lane and brake-checks). The guard's scenes use
a harsher script than the campaign attack's default (`GUARD_AGGRESSION`: it lines up 5 m ahead
of the ego, cuts in 0–8 m ahead, then brakes once at 8 m/s² for 2.5 s), as the guard's scripted
aggressor always did: the guard learns from crashes, and a brake check that stops as soon as
the ego backs off makes few of them.
"""

from __future__ import annotations

from riskmap.sim.drivers.aggressive import AggressiveParams, install_aggressive_neighbour

GUARD_AGGRESSION = AggressiveParams(pace_ahead_m=5.0, cut_in_behind_m=0.0, cut_in_ahead_m=8.0,
                                    brake_gap_m=15.0, brake_mps2=8.0, brake_hold_s=2.5)


class AggressorHook:
    """Callable hook for `riskmap.sim.worlds.highway_drive.drive_episode` (`DriveHooks.on_ready`); remembers
    the aggressor it installed.

    It runs after the planner's own hooks, so a guard or planner may already have replaced the
    ego vehicle object; the aggressor follows the ego `run.ego` names at every step.
    """

    def __init__(self, params: AggressiveParams = GUARD_AGGRESSION):
        self.params, self.aggressor = params, None

    def __call__(self, run) -> None:
        self.aggressor = install_aggressive_neighbour(run, self.params)
