"""Scripted aggressive neighbours: the "adversarial" scenes of the guard's data and evaluation.

No learned adversary is used here. At the start of an episode the neighbour nearest ahead of the
ego (within `search_m`, at most `lateral_m` to either side) is replaced by an `Aggressor`: an
IDM/MOBIL vehicle with reduced safety parameters (short time gap, small standstill distance,
no politeness) that paces the ego so as to sit a few metres ahead of it, cuts into the ego's lane
when it is in a side lane, and brakes hard for `brake_s` once it is close in front of the ego in
the ego's lane. At the intersection, where the two approach on different roads, the neighbour
nearest the ego that is not behind it instead rushes: reduced safety parameters and a target
speed of `rush_speed_mps`, so that it presses into the conflict zone instead of giving way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from riskmap.sim.episode import FAMILY_SETUPS


@dataclass(frozen=True)
class AggressorConfig:
    search_m: float = 40.0          # how far ahead of the ego the aggressor is picked
    lateral_m: float = 8.0          # and how far to either side
    time_gap_s: float = 0.5         # IDM time gap (default 1.5 s)
    distance_m: float = 2.0         # IDM standstill distance (default 10 m incl. a car length)
    pace_ahead_m: float = 5.0       # while approaching, keep this far ahead of the ego
    cut_in_ahead_m: tuple[float, float] = (0.0, 8.0)   # cut in when this far ahead of the ego
    brake_ahead_m: float = 15.0     # brake once in the ego's lane and at most this far ahead
    brake_mps2: float = 8.0         # hard braking (IDM's own limit is 6)
    brake_s: float = 2.5
    rush_search_m: float = 70.0     # intersection: pick among vehicles this close, not behind the ego
    rush_speed_mps: float = 13.0


def aggressor_class():
    """The `Aggressor` vehicle class (built lazily: highway-env is imported only when needed)."""
    from highway_env.vehicle.behavior import IDMVehicle

    class Aggressor(IDMVehicle):
        POLITENESS = 0.0
        LANE_CHANGE_MIN_ACC_GAIN = -10.0   # any side lane is welcome: the script decides

        def setup(self, ego, config: AggressorConfig, dt_s: float, rush: bool = False) -> None:
            self.ego, self.config, self.dt_s = ego, config, dt_s
            self.TIME_WANTED = config.time_gap_s
            self.DISTANCE_WANTED = config.distance_m + self.LENGTH
            self.phase, self.brake_left_s = ("rush" if rush else "approach"), 0.0
            if rush:
                self.target_speed = config.rush_speed_mps

        def _ahead_of_ego_m(self) -> tuple[float, float]:
            """(longitudinal, lateral) position relative to the ego, ego heading frame (m)."""
            d = self.position - self.ego.position
            c, s = np.cos(self.ego.heading), np.sin(self.ego.heading)
            return float(c * d[0] + s * d[1]), float(-s * d[0] + c * d[1])

        def change_lane_policy(self) -> None:
            lo, hi = self.config.cut_in_ahead_m
            ahead, _ = self._ahead_of_ego_m()
            ego_lane = getattr(self.ego, "lane_index", None)
            if (self.phase == "approach" and ego_lane is not None and ego_lane[:2] == self.lane_index[:2]
                    and ego_lane != self.lane_index and lo <= ahead <= hi):
                self.target_lane_index = ego_lane
                self.phase = "cut_in"

        def act(self, action=None):
            if self.crashed:
                return
            ahead, _ = self._ahead_of_ego_m()
            if self.phase == "approach":
                # Pace the ego so as to sit a few metres ahead of it, ready to cut in.
                gap_error = self.config.pace_ahead_m - ahead
                self.target_speed = max(float(self.ego.speed) + float(np.clip(0.5 * gap_error, -5, 5)), 0.0)
            super().act()
            same_lane = getattr(self.ego, "lane_index", None) == self.lane_index
            if self.phase in ("approach", "cut_in") and same_lane and 0 < ahead <= self.config.brake_ahead_m:
                self.phase, self.brake_left_s = "brake", self.config.brake_s
            if self.phase == "brake":
                self.action["acceleration"] = -self.config.brake_mps2
                self.brake_left_s -= self.dt_s
                if self.brake_left_s <= 0:
                    self.phase = "done"

    return Aggressor


def pick_victim(road, ego, config: AggressorConfig, rush: bool = False):
    """The neighbour nearest ahead of the ego inside the search box (rush: nearest not behind the
    ego within `rush_search_m`), or None."""
    c, s = np.cos(ego.heading), np.sin(ego.heading)
    best, best_d = None, np.inf
    for v in road.vehicles:
        if v is ego or not hasattr(v, "target_speed"):
            continue
        d = v.position - ego.position
        ahead, side = c * d[0] + s * d[1], -s * d[0] + c * d[1]
        if rush:
            ok, dist = ahead > -5.0 and np.hypot(ahead, side) <= config.rush_search_m, np.hypot(ahead, side)
        else:
            ok, dist = 0 < ahead <= config.search_m and abs(side) <= config.lateral_m, ahead
        if ok and dist < best_d:
            best, best_d = v, dist
    return best


def make_aggressive(run, config: AggressorConfig = AggressorConfig()):
    """Episode hook: replace the chosen neighbour of `run` (a `riskmap.sim.episode.Episode`) by an
    `Aggressor` at the same state. Returns the aggressor, or None when nobody qualifies."""
    road, ego = run.base.road, run.ego
    rush = run.setup is FAMILY_SETUPS["intersection"]
    victim = pick_victim(road, ego, config, rush)
    if victim is None:
        return None
    aggressor = aggressor_class().create_from(victim)
    aggressor.setup(ego, config, run.dt, rush)
    road.vehicles[road.vehicles.index(victim)] = aggressor
    run.recorder.adopt(aggressor, victim)
    return aggressor


class AggressorHook:
    """Callable hook for `riskmap.sim.rollout.drive_episode`; remembers the aggressor it installed.

    The ego it targets is looked up when the hook runs, after the planner's own hooks: a guard or
    planner may have replaced the ego vehicle object first, and the aggressor follows that one.
    """

    def __init__(self, config: AggressorConfig = AggressorConfig()):
        self.config, self.aggressor = config, None

    def __call__(self, run) -> None:
        self.aggressor = make_aggressive(run, self.config)
