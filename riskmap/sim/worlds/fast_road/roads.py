"""The fast road's classes: `FastRoadNetwork`, `FastRoad` and `FastRegulatedRoad`, subclasses of
highway-env 1.12's. Importing this module imports highway-env; `riskmap.sim.worlds.fast_road.upgrade`
imports it only once that version is found."""

from __future__ import annotations

import inspect

import numpy as np
from highway_env import utils
from highway_env.road.lane import CircularLane, PolyLane, SineLane, StraightLane
from highway_env.road.regulation import RegulatedRoad
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import Landmark, RoadObject

from riskmap.sim.worlds.fast_road.act_window import _IDM_METHODS, _ActWindow
from riskmap.sim.worlds.fast_road.collisions import _collision_candidates
from riskmap.sim.worlds.fast_road.lanes import _LaneFinder
from riskmap.sim.worlds.fast_road.right_of_way import _HORIZON, _STEP, _RuleCheck
from riskmap.sim.worlds.fast_road.switch import ENV_VAR

stock_handle, stock_colliding = RoadObject.handle_collisions, RoadObject._is_colliding
pure_predictions = (ControlledVehicle.predict_trajectory_constant_speed,
                    Vehicle.predict_trajectory_constant_speed)
lane_methods = tuple({cls.local_coordinates
                      for cls in (StraightLane, SineLane, CircularLane, PolyLane)})
defaults = inspect.signature(RegulatedRoad.is_conflict_possible).parameters
shared_predictions = (defaults["horizon"].default, defaults["step"].default) == (_HORIZON, _STEP)
stock_conflict = RegulatedRoad.is_conflict_possible


class FastRoadNetwork(RoadNetwork):
    """A `RoadNetwork` whose closest-lane look-up skips lanes that cannot be the closest, and
    which places many points along a route at once."""

    fast_road = True

    def add_lane(self, _from, _to, lane) -> None:
        super().add_lane(_from, _to, lane)
        self.__dict__.pop("_fast_lanes", None)

    def _finder(self) -> _LaneFinder:
        # Rebuilt whenever the graph is replaced or its number of lanes changes.
        graph = self.graph
        count = sum(len(lanes) for to_dict in graph.values() for lanes in to_dict.values())
        cached = self.__dict__.get("_fast_lanes")
        if cached is None or cached[0] is not graph or cached[1] != count:
            entries = [((_from, _to, _id), lane) for _from, to_dict in graph.items()
                       for _to, lanes in to_dict.items() for _id, lane in enumerate(lanes)]
            cached = (graph, count, _LaneFinder(entries, StraightLane, SineLane, CircularLane))
            self.__dict__["_fast_lanes"] = cached
        return cached[2]

    def get_closest_lane_index(self, position, heading=None):
        found = self._finder().closest(position, heading)
        if found is None:
            return super().get_closest_lane_index(position, heading)
        return found

    def positions_along_route(self, route, longitudinals, current_lane_index,
                              lateral=0.0, headings: bool = False):
        """[P, 2]: `position_heading_along_route(route, l, lateral, current_lane_index)[0]`
        for each l in `longitudinals`, and with `headings` also the list of the `[1]`s.
        Straight lanes are computed for all their points at once, with the same
        elementwise operations as `StraightLane.position`; other lanes point by point."""
        longitudinal = np.array(longitudinals, dtype=np.float64)
        n = longitudinal.shape[0]

        kept_id: list = []

        def lane_at(k: int):
            # A route step without a lane id keeps the current lane's id, or takes lane 0
            # where the current road has no lane of that id (highway-env's convention).
            _from, _to, _id = route[k]
            if _id is None:
                if not kept_id:
                    road_from, road_to, current = current_lane_index
                    kept_id.append(current if current < len(self.graph[road_from][road_to]) else 0)
                _id = kept_id[0]
            return self.get_lane((_from, _to, _id))

        segment = np.zeros(n, dtype=np.int64)
        moving = np.ones(n, dtype=bool)
        for k in range(len(route) - 1):
            length = lane_at(k).length
            moves = moving & (longitudinal > length)
            longitudinal[moves] = longitudinal[moves] - length
            segment[moves] = k + 1
            moving = moves
        out = np.empty((n, 2), dtype=np.float64)
        lanes = [None] * n
        for k in np.unique(segment).tolist():
            rows = np.flatnonzero(segment == k)
            lane = lane_at(k)
            for r in rows.tolist():
                lanes[r] = lane
            if type(lane) is StraightLane:
                out[rows] = (lane.start + longitudinal[rows, None] * lane.direction
                             + lateral * lane.direction_lateral)
            else:
                for r in rows.tolist():
                    out[r] = lane.position(longitudinal[r], lateral)
        if not headings:
            return out
        return out, [lanes[r].heading_at(longitudinal[r]) for r in range(n)]

    def predict_constant_speed(self, vehicle, times: np.ndarray):
        """`ControlledVehicle.predict_trajectory_constant_speed(vehicle, times)` (for a
        vehicle on this network): positions [T, 2] and the list of headings."""
        # Along its route (or its lane), from where it is, at its speed, on the centre line.
        s_now = vehicle.lane.local_coordinates(vehicle.position)[0]
        along = vehicle.route if vehicle.route else [vehicle.lane_index]
        return self.positions_along_route(along, s_now + vehicle.speed * times,
                                          vehicle.lane_index, lateral=0, headings=True)


class FastRoad(Road):
    """highway-env's `Road` with its vehicles acting in an act window (`_ActWindow`: lane
    coordinates remembered, neighbour searches answered from per-lane lists) and collision
    checks only for pairs whose bounding circles can meet."""

    fast_road = True
    _fast_window = None           # the act window while the vehicles act

    def act(self) -> None:
        window = _ActWindow(self, Landmark, lane_methods)
        self._fast_window = window
        try:
            for vehicle in self.vehicles:
                window.trusted = (type(vehicle) is IDMVehicle
                                  and vehicle.__dict__.keys().isdisjoint(_IDM_METHODS))
                vehicle.act()
        finally:
            self.__dict__.pop("_fast_window", None)
            window.close()
        if not window.unchanged(self):
            raise RuntimeError(
                "a vehicle moved, or the road's vehicles changed, while the vehicles acted; "
                f"the fast road cannot be used here (set {ENV_VAR}=0 or make_env(fast=False))")

    def neighbour_vehicles(self, vehicle, lane_index=None):
        window = self._fast_window
        if window is not None and window.trusted and not self.neighbour_vehicles_connected_lanes:
            return window.neighbours(vehicle, lane_index)
        return super().neighbour_vehicles(vehicle, lane_index)

    def step(self, dt: float) -> None:
        if not all(type(m).handle_collisions is stock_handle
                   and type(m)._is_colliding is stock_colliding
                   and "handle_collisions" not in vars(m) and "_is_colliding" not in vars(m)
                   for m in self.vehicles + self.objects):
            return super().step(dt)                    # highway-env's own, every pair
        for vehicle in self.vehicles:
            vehicle.step(dt)
        vehicles = self.vehicles
        members = vehicles + self.objects
        pairs = _collision_candidates(vehicles, members, dt) if vehicles else []
        if pairs is None:           # no prefilter: every pair, in highway-env's order
            pairs = [(i, j) for i in range(len(vehicles)) for j in range(i + 1, len(members))]
        for i, j in pairs:
            vehicles[i].handle_collisions(members[j], dt)


def predict(vehicle, times):
    """A vehicle's `predict_trajectory_constant_speed(times)`, or None for a vehicle whose
    prediction is not highway-env's `ControlledVehicle` or `Vehicle` one (it is then asked
    for every pair, as highway-env does)."""
    method = type(vehicle).predict_trajectory_constant_speed
    if method not in pure_predictions or "predict_trajectory_constant_speed" in vars(vehicle):
        return None
    network = vehicle.road.network if vehicle.road is not None else None
    if method is pure_predictions[0] and isinstance(network, FastRoadNetwork):
        return network.predict_constant_speed(vehicle, times)
    return vehicle.predict_trajectory_constant_speed(times)


class FastRegulatedRoad(RegulatedRoad, FastRoad):
    """highway-env's `RegulatedRoad` on a `FastRoad`: its own `step` and
    `enforce_road_rules`, whose pair tests (`is_conflict_possible`) share one prediction
    per vehicle and check (`_RuleCheck`)."""

    _fast_rule_check = None       # the rule check under way

    def enforce_road_rules(self) -> None:
        if not shared_predictions:
            return super().enforce_road_rules()
        check = _RuleCheck(self, predict, utils.rotated_rectangles_intersect)
        self._fast_rule_check = check
        try:
            result = super().enforce_road_rules()      # RegulatedRoad's own
        finally:
            self.__dict__.pop("_fast_rule_check", None)
        if not check.unchanged():
            raise RuntimeError(
                "a vehicle moved while the road's rules were enforced; the fast road cannot "
                f"be used here (set {ENV_VAR}=0 or make_env(fast=False))")
        return result

    @staticmethod
    def is_conflict_possible(v1, v2, horizon: int = 3, step: float = 0.25) -> bool:
        check = getattr(getattr(v1, "road", None), "_fast_rule_check", None)
        if check is not None and horizon == _HORIZON and step == _STEP:
            known = check.conflict(v1, v2)
            if known:
                return True
            if known is not None:
                return None                # highway-env's answer when it finds no conflict
        return stock_conflict(v1, v2, horizon, step)
