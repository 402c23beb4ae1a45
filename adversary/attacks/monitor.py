"""Per-episode measurements of a stress-test job, taken through drive_episode's hooks
(`DriveHooks.on_reset`, `.on_step`).

Definitions (STRIVE's metrics as CRASH uses them, adapted to highway-env):

- collision: highway-env's own crash flag on the ego (its boxes intersect). The partner is the
  nearest other vehicle that highway-env flagged as crashed at that step (else the nearest one).
- kinematic value: |v_ego - v_partner| (m/s, velocity vectors) at the collision step.
- collision type: `riskmap.sim.records.metrics.coarse_collision_type` (head-on, rear-end either way,
  sideswipe, side (angle), from the relative heading and the partner's place in the ego's frame).
- off-road: `riskmap.sim.records.metrics.centre_off_lane`: a vehicle's centre more than
  `off_road_margin_m` outside every lane of the network, checked once a simulated second for the
  adversary and for the other vehicles within `radius_m` of the ego, up to the collision (later
  off-road moves are consequences).
- Safety %: `riskmap.sim.records.metrics.closing_dangerous_encounters` with `ClosingSafetyConfig` (the
  campaign reading: box gap under `close_gap_m`, or gap / closing speed under `ttc_s`, for every
  vehicle within `radius_m`), at 2 Hz, the planner paper's step.
"""

from __future__ import annotations

import numpy as np

from riskmap.sim.records.metrics import ClosingSafetyConfig as SafetyConfig
from riskmap.sim.records.metrics import centre_off_lane as off_network
from riskmap.sim.records.metrics import closing_dangerous_encounters, safety_pct
from riskmap.sim.records.metrics import coarse_collision_type as collision_type

# The names campaigns and their tests import from here.
__all__ = ["EpisodeMonitor", "SafetyConfig", "collision_type", "off_network"]


class EpisodeMonitor:
    """Observer for `drive_episode`: runs the attack's hooks, then measures (module docstring)."""

    def __init__(self, attack, safety: SafetyConfig, control_hz: int):
        self.attack, self.safety = attack, safety
        self.every_safety = max(1, control_hz // 2)     # 2 Hz, the planner paper's step
        self.every_off_road = control_hz                # once a simulated second
        self.run = None
        self.encounters = self.dangerous = 0
        self.collision: dict | None = None
        self.collision_step: int | None = None
        self.adversary_off_road = self.other_off_road = False

    def start(self, run) -> None:
        self.run = run
        self.attack.start(run)

    def step(self, run) -> None:
        self.attack.step(run)
        if self.collision is not None:
            return
        road, ego = run.base.road, run.ego
        if ego.crashed:
            self._record_collision(road, ego, run.steps)
            return
        if run.steps % self.every_safety == 0:
            self._count_encounters(road, ego)
        if run.steps % self.every_off_road == 0:
            self._check_off_road(road, ego)

    def _count_encounters(self, road, ego) -> None:
        dangerous, encounters = closing_dangerous_encounters(ego, road.vehicles, self.safety)
        self.dangerous += dangerous
        self.encounters += encounters

    def _check_off_road(self, road, ego) -> None:
        adversary, margin = self.attack.adversary, self.safety.off_road_margin_m
        for other in road.vehicles:
            if other is ego:
                continue
            if other is adversary:
                self.adversary_off_road |= off_network(road, other, margin)
            elif (not self.other_off_road
                  and np.linalg.norm(other.position - ego.position) <= self.safety.radius_m):
                self.other_off_road = off_network(road, other, margin)

    def _record_collision(self, road, ego, step: int) -> None:
        others = [v for v in road.vehicles if v is not ego]
        crashed = [v for v in others if v.crashed] or others
        partner = min(crashed, key=lambda v: float(np.linalg.norm(v.position - ego.position)))
        self.collision_step = step
        self.collision = {
            "partner_is_adversary": partner is self.attack.adversary,
            "partner_id": self.run.recorder.known_id(partner),      # its row in the recorder's tracks
            "kinematic_mps": float(np.linalg.norm(ego.velocity - partner.velocity)),
            "type": collision_type(ego, partner),
            "time_s": step * self.run.dt,
        }

    def summary(self) -> dict:
        c = self.collision
        return {
            "has_adversary": self.attack.adversary is not None,
            "collided_with_adversary": bool(c and c["partner_is_adversary"]),
            "collision_type": c["type"] if c else None,
            "collision_time_s": c["time_s"] if c else None,
            "kinematic_mps": c["kinematic_mps"] if c else None,
            "adversary_off_road": self.adversary_off_road if self.attack.adversary is not None else None,
            "other_off_road": self.other_off_road,
            "encounters": self.encounters,
            "dangerous_encounters": self.dangerous,
            "safety_pct": safety_pct(self.dangerous, self.encounters),
        }
