"""Static (parked and stopped) vehicles added to a simulated highway-env episode.

highway-env's traffic never stands still, so CRASH's Motion-Aware Masking (an agent that has not
moved over the window's history cannot be the adversary) has nothing to mask in its scenes.
`place_static_vehicles` adds `count` vehicles that do not move, right after the episode's reset,
where such vehicles are found:

- highway: stopped / broken-down cars on the carriageway. Each goes on the rightmost lane with
  probability `rightmost_share` (the usual place of a breakdown), else on any lane, mostly ahead
  of the ego (`ahead_m`), sometimes behind it (`behind_m`, `behind_share`). A candidate spot is
  drawn again (up to `attempts` times) while it is closer than `clearance_m` to any vehicle, or
  while a vehicle on the same lane behind it could not stop before it braking at `brake_mps2`
  (so that the spot is not an unavoidable crash for the traffic or the ego at t = 0).
- intersection: a red-light queue: the cars stand bumper to bumper (`queue_gap_m`) on the
  incoming lane of an approach other than the ego's, the first `stop_line_gap_m` before the
  junction; a queue longer than its lane's room (`queue_room_m` left free at the lane's start,
  where the env spawns its traffic) goes on on the next approach. Traffic cars that stand where
  the queue stands, or too close behind it to stop, are removed from the road: they would be
  waiting in that queue.

Every static car stays ON a lane, never on a shoulder: CRASH's judge counts every non-ego,
non-adversary window vehicle whose box is more than 5% outside the lane polygons as an "other
off-road" event, so a car parked beside the lanes would count as one in every scene it is in.

The cars are plain highway-env vehicles with speed 0 that ignore every action (`StaticVehicle`):
`road.step` leaves them exactly where they are (0 m/s times dt), unless another vehicle crashes
into them (highway-env then pushes both boxes apart). IDM/MOBIL traffic sees them as it sees any
vehicle on its lane: it brakes behind them or changes lanes. The recorder records them like any
other vehicle (kind VEHICLE), so a log replay replays them too. They join the road after the
env's own vehicles, so they are the last agents the recorder numbers at the first step; on the
highway the env's vehicles start exactly as they do without static cars.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from rasterize.errors import InputError
from riskmap.sim.records.metrics import min_box_gap, vehicle_box

STATIC_FAMILIES = ("highway", "intersection")   # the families with a placement rule
# More do not fit around the ego in most highway episodes (12: 4 of 40 episodes of seed 500 have
# no room); a sweep over episodes would skip one after another.
MAX_STATIC_AGENTS = 10


@dataclass(frozen=True)
class StaticPlacement:
    """Where static vehicles go (module docstring); metres, m/s², shares in [0, 1]."""

    # highway: distance ahead of the ego at t = 0. The ego covers ~50 m before an attack at
    # t0 = 2 s and the attack window reaches 60 m around it, so most of these are in the window
    # (CRASH's masking has something to mask); the farther ones enter it later, ahead of the ego.
    ahead_m: tuple[float, float] = (40.0, 150.0)
    behind_m: tuple[float, float] = (20.0, 80.0)    # highway: distance behind the ego
    behind_share: float = 0.2                       # highway: share placed behind the ego
    rightmost_share: float = 0.5                    # highway: share on the rightmost lane
    clearance_m: float = 2.0                        # smallest box gap to any vehicle
    brake_mps2: float = 4.0                         # a follower on the lane must stop at this
    follower_margin_m: float = 5.0                  # ... and still have this much room left
    attempts: int = 500                             # highway: spots drawn per vehicle at most
    queue_gap_m: tuple[float, float] = (1.5, 2.0)   # intersection: bumper-to-bumper gaps
    stop_line_gap_m: tuple[float, float] = (0.5, 2.0)  # intersection: front car to the junction
    queue_room_m: float = 20.0                      # intersection: lane start kept free


@functools.lru_cache(maxsize=1)
def static_vehicle_class():
    """The highway-env Vehicle class of a static car (made once, on first use, so that importing
    this module does not import highway-env)."""
    from highway_env.vehicle.kinematics import Vehicle

    class StaticVehicle(Vehicle):
        """A car that stands still: speed 0, no controller, every action ignored."""

        def __init__(self, road, position, heading: float, lane_index):
            super().__init__(road, np.asarray(position, dtype=np.float64), heading, 0.0)
            # intersection-v0's `_clear_vehicles` removes every vehicle without a route, and the
            # yielding teacher reads the others' routes: a parked car's route is its own lane.
            self.route = [lane_index]

        def act(self, action=None) -> None:
            pass

        def predict_trajectory_constant_speed(self, times: np.ndarray):
            # It stays put. (highway-env's own prediction simulates a deep copy of the vehicle,
            # road and all, which the intersection's right-of-way rule would ask twice a second.)
            return [self.position.copy() for _ in times], [self.heading] * len(times)

    return StaticVehicle


def is_static(vehicle) -> bool:
    """Whether `vehicle` is a static car of this module."""
    return isinstance(vehicle, static_vehicle_class())


def _on_lane_behind(lane, vehicle, s: float, length_m: float) -> float | None:
    """The bumper gap (m) from `vehicle` to a car centred at `s` on `lane`, if `vehicle` is on
    that lane (its box reaches into it) and behind that car; None otherwise."""
    s_v, lateral = lane.local_coordinates(vehicle.position)
    if abs(lateral) >= 0.5 * (lane.width_at(s_v) + vehicle.WIDTH) or s_v >= s:
        return None
    return s - s_v - 0.5 * (length_m + vehicle.LENGTH)


def _near(box: np.ndarray, vehicles, within_m: float) -> list:
    """The vehicles whose boxes may come within `within_m` of `box` (by their centres: the box
    gap is at least the centre distance less both half-diagonals), the others need no box test."""
    centre, reach = box.mean(axis=0), 0.5 * float(np.linalg.norm(box[0] - box[2])) + within_m
    return [v for v in vehicles
            if np.hypot(*(v.position - centre)) < reach + 0.5 * float(np.hypot(v.LENGTH, v.WIDTH))]


def _spot_is_free(lane, s: float, box: np.ndarray, length_m: float, vehicles, config: StaticPlacement) -> bool:
    near = _near(box, vehicles, config.clearance_m)
    if min_box_gap(box, (vehicle_box(v) for v in near)) < config.clearance_m:
        return False
    for v in vehicles:
        gap = _on_lane_behind(lane, v, s, length_m)
        if gap is not None and gap < max(v.speed, 0.0) ** 2 / (2 * config.brake_mps2) + config.follower_margin_m:
            return False
    return True


def _in_the_way(vehicle, lane, boxes: list, tail_s: float, config: StaticPlacement) -> bool:
    """Whether `vehicle` is within `clearance_m` of a queue (`boxes`) whose last car stands at
    `tail_s` on `lane`, or behind it on that lane, too close to stop."""
    if min_box_gap(vehicle_box(vehicle), boxes) < config.clearance_m:
        return True
    gap = _on_lane_behind(lane, vehicle, tail_s, static_vehicle_class().LENGTH)
    return gap is not None and gap < (max(vehicle.speed, 0.0) ** 2 / (2 * config.brake_mps2)
                                      + config.follower_margin_m)


def _make(road, lane_index, s: float):
    lane = road.network.get_lane(lane_index)
    return static_vehicle_class()(road, lane.position(s, 0.0), lane.heading_at(s), lane_index)


def _place_on_highway(road, ego, count: int, rng: np.random.Generator, config: StaticPlacement) -> list:
    _from, _to, ego_lane_id = ego.lane_index
    lanes = road.network.graph[_from][_to]
    s_ego = lanes[ego_lane_id].local_coordinates(ego.position)[0]
    placed = []
    for k in range(count):
        # The side is drawn once per vehicle: redrawn with the spot, it would favour the empty
        # road behind the ego (highway-env puts its traffic ahead of the ego).
        behind = rng.random() < config.behind_share
        for _ in range(config.attempts):
            # highway-env numbers its parallel lanes from the left: the last is the rightmost.
            lane_id = len(lanes) - 1 if rng.random() < config.rightmost_share else int(rng.integers(len(lanes)))
            s = s_ego - rng.uniform(*config.behind_m) if behind else s_ego + rng.uniform(*config.ahead_m)
            lane = lanes[lane_id]
            length_m = static_vehicle_class().LENGTH
            if not length_m <= s <= lane.length - length_m:
                continue
            vehicle = _make(road, (_from, _to, lane_id), s)
            if _spot_is_free(lane, s, vehicle_box(vehicle), length_m, road.vehicles, config):
                road.vehicles.append(vehicle)
                placed.append(vehicle)
                break
        else:
            raise InputError(f"could not place static vehicle {k + 1} of {count} on the highway with "
                             f"{config.clearance_m} m of clearance in {config.attempts} tries; use fewer "
                             "--static-agents")
    return placed


def _place_queues(road, ego, count: int, rng: np.random.Generator, config: StaticPlacement) -> list:
    network = road.network
    # Route entries name lanes (from, to, id) with id None where any lane of the road will do.
    route = {tuple(index[:2]) for index in (getattr(ego, "route", None) or [])} | {tuple(ego.lane_index[:2])}
    # The incoming lanes (outer node "o*" to inner "ir*") of every approach but the ego's.
    incoming = [(a, b, i) for a in network.graph for b in network.graph[a]
                for i in range(len(network.graph[a][b]))
                if a.startswith("o") and b.startswith("ir") and (a, b) not in route]
    if not incoming:
        raise InputError("this intersection has no incoming lane outside the ego's route to queue "
                         "static vehicles on; use --static-agents 0")
    order = [incoming[j] for j in rng.permutation(len(incoming))]
    cls = static_vehicle_class()
    placed = []
    for lane_index in order:
        lane = network.get_lane(lane_index)
        s = lane.length - rng.uniform(*config.stop_line_gap_m) - 0.5 * cls.LENGTH
        queue = []
        while len(placed) + len(queue) < count and s - 0.5 * cls.LENGTH >= config.queue_room_m:
            queue.append(_make(road, lane_index, s))
            s -= cls.LENGTH + rng.uniform(*config.queue_gap_m)
        if not queue:
            continue
        boxes = [vehicle_box(v) for v in queue]
        tail_s = lane.local_coordinates(queue[-1].position)[0]
        if any(_in_the_way(v, lane, boxes, tail_s, config) for v in [ego, *placed]):
            continue
        # Traffic where the queue stands (or too close behind it to stop) would be in the queue.
        keep = {id(ego)} | {id(v) for v in placed}
        road.vehicles = [v for v in road.vehicles
                         if id(v) in keep or not _in_the_way(v, lane, boxes, tail_s, config)] + queue
        placed += queue
        if len(placed) == count:
            return placed
    raise InputError(f"could only queue {len(placed)} of {count} static vehicles at the intersection's "
                     "approaches; use fewer --static-agents")


def place_static_vehicles(road, ego, family: str, count: int, rng: np.random.Generator,
                          config: StaticPlacement = StaticPlacement()) -> list:
    """Add `count` static vehicles to `road` around `ego` for scenario `family` (module docstring)
    and return them. InputError for a family without a placement rule, or where they do not fit."""
    if count < 0:
        raise InputError(f"static vehicles: count={count} must be 0 or more")
    if count == 0:
        return []
    if family == "highway":
        return _place_on_highway(road, ego, count, rng, config)
    if family == "intersection":
        return _place_queues(road, ego, count, rng, config)
    raise InputError(f"static vehicles are placed in the {', '.join(STATIC_FAMILIES)} families only, "
                     f"not in {family}; use --static-agents 0")
