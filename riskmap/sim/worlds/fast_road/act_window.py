"""The act window (`_ActWindow`): lane coordinates remembered and neighbour searches answered
from per-lane lists while the road's vehicles act."""

from __future__ import annotations

import bisect
import math
import operator

import numpy as np

from riskmap.sim.worlds.fast_road.tolerances import _TOL_M, _TOL_REL

# What highway-env's `IDMVehicle.act` calls on the deciding vehicle itself; one of them set on
# the instance (or a vehicle of another class) makes its neighbour searches highway-env's own.
_IDM_METHODS = frozenset({"act", "follow_road", "change_lane_policy", "mobil", "steering_control",
                          "acceleration", "desired_gap", "lane_distance_to"})
_FLOAT64 = np.dtype(np.float64)
_SCALARS = (float, np.float64)


def _remembering(local_coordinates):
    """`local_coordinates` (a lane's own bound method) keeping its answers. The answer is a
    function of the lane, which does not change, and of the position's numbers: a float64 vector
    is known by its bytes. Anything else, and any answer that is not a tuple of floats, is
    computed every time."""
    known: dict = {}
    find = known.get

    def remembered(position):
        if type(position) is np.ndarray and position.dtype is _FLOAT64 and position.ndim == 1:
            key = position.tobytes()
            found = find(key)
            if found is None:
                found = local_coordinates(position)
                if type(found) is tuple and all(type(x) in _SCALARS for x in found):
                    known[key] = found
            return found
        return local_coordinates(position)

    remembered.forget = known.clear
    return remembered


class _ActWindow:
    """While the road's vehicles act (`Road.act`) nobody moves, turns or changes speed, and the
    road keeps its vehicles and objects (`unchanged`, checked when all have acted). Meanwhile:

    - the network's lanes of highway-env's own classes remember their `local_coordinates`
      answers (`_remembering`: an instance attribute, removed by `close`);
    - a neighbour search asked while a plain `IDMVehicle` acts (`trusted`: highway-env's code,
      which moves nothing) is answered from the lane's members, listed once per window with
      highway-env's own coordinates and `on_lane` test and sorted along the lane
      (`neighbours`); any other vehicle's searches are highway-env's own, since its code might
      show the road other vehicles or positions for a moment.
    """

    __slots__ = ("finder", "installed", "landmark", "members", "road", "snapshot", "tables",
                 "trusted", "xy")

    def __init__(self, road, landmark, lane_methods: tuple):
        self.road = road
        self.members = road.vehicles + road.objects
        self.landmark = landmark
        self.snapshot = (list(road.vehicles), list(road.objects), _states(self.members))
        self.tables: dict = {}        # lane -> ([s sorted], [member]) of the members on it
        self.trusted = False
        finder = getattr(road.network, "_finder", None)
        self.finder = finder() if callable(finder) else None
        self.xy = None                # [[x, y]] of the members, for `_maybe_on`
        self.installed: list = []     # (lane's __dict__, remembering function)
        for _, lane in (self.finder.entries if self.finder is not None else ()):
            attrs = getattr(lane, "__dict__", None)
            if attrs is None or "local_coordinates" in attrs \
                    or type(lane).local_coordinates not in lane_methods:
                continue
            remembered = _remembering(lane.local_coordinates)
            attrs["local_coordinates"] = remembered
            self.installed.append((attrs, remembered))

    def close(self) -> None:
        """Give the lanes back their own `local_coordinates` and forget every answer."""
        for attrs, remembered in self.installed:
            if attrs.get("local_coordinates") is remembered:
                del attrs["local_coordinates"]
            remembered.forget()
        self.installed = []
        self.tables.clear()
        self.trusted = False

    def neighbours(self, vehicle, lane_index):
        """`Road.neighbour_vehicles(vehicle, lane_index)` (without connected lanes): the nearest
        member ahead (a longitudinal coordinate at least the vehicle's; among equals the last in
        the road's order) and behind (strictly less; among equals the first), `vehicle` aside."""
        index = lane_index if lane_index else vehicle.lane_index
        if not index:
            return None, None
        lane = self.road.network.get_lane(index)
        s = lane.local_coordinates(vehicle.position)[0]
        if math.isnan(s):                                   # nothing compares with NaN
            return None, None
        keys, members = self.table(lane)
        n = len(keys)
        start = bisect.bisect_left(keys, s)                 # keys[:start] < s <= keys[start:]
        ahead = behind = None
        k = start
        while ahead is None and k < n:                      # the smallest key >= s
            end = bisect.bisect_right(keys, keys[k], k)
            for j in range(end - 1, k - 1, -1):
                if members[j] is not vehicle:
                    ahead = members[j]
                    break
            k = end
        k = start
        while behind is None and k > 0:                     # the largest key < s
            first = bisect.bisect_left(keys, keys[k - 1], 0, k)
            for j in range(first, k):
                if members[j] is not vehicle:
                    behind = members[j]
                    break
            k = first
        return ahead, behind

    def table(self, lane) -> tuple[list, list]:
        """The road's members (landmarks aside) that highway-env's neighbour search counts on
        `lane` (`on_lane` with its 1 m margin) and whose longitudinal coordinate is a number,
        sorted by that coordinate and then by their order on the road."""
        found = self.tables.get(lane)
        if found is not None:
            return found
        members, rows = self.members, []
        for k, surely in self._maybe_on(lane):
            v = members[k]
            if isinstance(v, self.landmark):
                continue
            s_v, lat_v = lane.local_coordinates(v.position)
            if not math.isnan(s_v) and (surely or lane.on_lane(v.position, s_v, lat_v, margin=1)):
                rows.append((s_v, k))
        rows.sort()
        found = self.tables[lane] = ([s_v for s_v, _ in rows], [members[k] for _, k in rows])
        return found

    def _maybe_on(self, lane):
        """[(index, surely)] of the members that may be on `lane`, `surely` where `on_lane` is
        True beyond doubt. From the members' coordinates in floats, with a rounding margin: for
        a straight lane of the network, against `on_lane`'s limits (lateral and longitudinal);
        for a circular one, against its lateral limit (|radius - distance to the centre|), never
        surely; for other lanes all are kept, none surely."""
        n = len(self.members)
        finder = self.finder
        straight = None if finder is None else finder.straight_lanes.get(lane)
        circular = None if finder is None or straight is not None else finder.circular_lanes.get(lane)
        if straight is None and circular is None:
            return [(k, False) for k in range(n)]
        if self.xy is None:
            try:
                xy = [m.position.tolist() for m in self.members]
                ok = all(len(p) == 2 and math.isfinite(p[0]) and math.isfinite(p[1]) for p in xy)
            except (AttributeError, TypeError):
                ok = False
            self.xy = xy if ok else False
        if self.xy is False:
            return [(k, False) for k in range(n)]
        keep = []
        if circular is not None:
            cx, cy, radius, half_width = circular
            for k, (x, y) in enumerate(self.xy):
                dx, dy = x - cx, y - cy
                tol = _TOL_M + _TOL_REL * (abs(dx) + abs(dy) + radius)
                if abs(math.hypot(dx, dy) - radius) <= half_width + tol:
                    keep.append((k, False))
            return keep
        sx, sy, d0, d1, l0, l1, length, half_width, vehicle_length = straight
        for k, (x, y) in enumerate(self.xy):
            dx, dy = x - sx, y - sy
            tol = _TOL_M + _TOL_REL * (abs(dx) + abs(dy) + length)
            # on_lane(margin=1): |lateral| <= width / 2 + 1, -L_v <= longitudinal < length + L_v
            lateral = abs(dx * l0 + dy * l1)
            if lateral > half_width + tol:
                continue
            s = dx * d0 + dy * d1
            if s < -vehicle_length - tol or s > length + vehicle_length + tol:
                continue
            keep.append((k, lateral < half_width - tol
                         and -vehicle_length + tol < s < length + vehicle_length - tol))
        return keep

    def unchanged(self, road) -> bool:
        vehicles, objects, states = self.snapshot
        return (len(road.vehicles) == len(vehicles) and len(road.objects) == len(objects)
                and all(map(operator.is_, road.vehicles, vehicles))
                and all(map(operator.is_, road.objects, objects))
                and _states(self.members) == states)


def _states(members: list) -> tuple:
    """What an act must leave unchanged: positions (exactly), headings and speeds."""
    try:
        positions = [m.position.tobytes() for m in members]
    except AttributeError:
        positions = [repr(m.position) for m in members]
    return (positions, [getattr(m, "heading", None) for m in members],
            [getattr(m, "speed", None) for m in members])
