"""Per-episode measurements of a stress-test job, taken through drive_episode's hooks
(`DriveHooks.on_reset`, `.on_step`).

Definitions (STRIVE's metrics as CRASH uses them, adapted to highway-env):

- collision: highway-env's own crash flag on the ego (its boxes intersect). The partner is the
  nearest other vehicle that highway-env flagged as crashed at that step (else the nearest one).
- kinematic value: |v_ego - v_partner| (m/s, velocity vectors) at the collision step.
- collision type from the partner's heading relative to the ego's, dpsi, and its position in the
  ego's frame: |dpsi| >= 150 deg head-on; |dpsi| <= 30 deg and laterally overlapping (|lateral|
  < half the sum of the widths) rear-end, "ego rear-ends" when the partner is ahead and
  "ego rear-ended" when behind; |dpsi| <= 30 deg otherwise sideswipe; else side (angle).
- off-road: a vehicle's centre more than `off_road_margin_m` outside every lane of the network,
  checked once a simulated second for the adversary and for the other vehicles within
  `radius_m` of the ego, up to the collision (later off-road moves are consequences).
- Safety % (planner paper, Table I): the share of encounters, over all steps at 2 Hz, in which
  the ego is dangerously close. An encounter is (step, other vehicle within `radius_m`); it is
  dangerously close when the bumper-to-bumper box gap is under `close_gap_m` or the
  time-to-collision (gap / closing speed along the line of centres, when closing) is under `ttc_s`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.frames import box_corners
from rasterize.geometry import box_gap


@dataclass(frozen=True)
class SafetyConfig:
    close_gap_m: float = 2.0
    ttc_s: float = 1.5
    radius_m: float = 40.0
    off_road_margin_m: float = 1.0


def _box(vehicle) -> np.ndarray:
    # highway-env frame throughout: gaps and overlaps do not depend on the handedness.
    return box_corners(vehicle.position, [np.cos(vehicle.heading), np.sin(vehicle.heading)],
                       vehicle.LENGTH, vehicle.WIDTH)


def off_network(road, vehicle, margin_m: float) -> bool:
    lane = road.network.get_lane(road.network.get_closest_lane_index(vehicle.position,
                                                                     vehicle.heading))
    return not lane.on_lane(vehicle.position, margin=margin_m)


def collision_type(ego, partner) -> str:
    dpsi = (partner.heading - ego.heading + np.pi) % (2 * np.pi) - np.pi
    d = partner.position - ego.position
    c, s = np.cos(ego.heading), np.sin(ego.heading)
    forward, lateral = d[0] * c + d[1] * s, -d[0] * s + d[1] * c
    if abs(dpsi) >= np.radians(150):
        return "head-on"
    if abs(dpsi) <= np.radians(30):
        if abs(lateral) < 0.5 * (ego.WIDTH + partner.WIDTH):
            return "ego rear-ends" if forward > 0 else "ego rear-ended"
        return "sideswipe"
    return "side (angle)"


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
        mine = _box(ego)
        for other in road.vehicles:
            d = other.position - ego.position
            dist = float(np.linalg.norm(d))
            if other is ego or dist > self.safety.radius_m:
                continue
            gap = box_gap(mine, _box(other))
            closing = -float(np.dot(other.velocity - ego.velocity, d)) / max(dist, 1e-9)
            ttc = gap / closing if closing > 1e-9 else np.inf
            self.encounters += 1
            self.dangerous += int(gap < self.safety.close_gap_m or ttc < self.safety.ttc_s)

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
            "safety_pct": 100.0 * self.dangerous / self.encounters if self.encounters else 0.0,
        }
