"""A faster highway-env road: the same vehicle states every step, bit for bit, in less time.

highway-env answers its road's questions by brute force in Python, every simulation step: every
vehicle is tested against every other for a collision (`Road.step`), every neighbour search
projects every vehicle onto the lane (`Road.neighbour_vehicles`), every lane look-up measures the
distance to every lane of the network (`RoadNetwork.get_closest_lane_index`), and the
intersection's right-of-way rule predicts both vehicles of every pair again
(`RegulatedRoad.is_conflict_possible`, asked by `enforce_road_rules` for each pair).
`upgrade_road` turns one road and its network into subclasses that give the same answers
without the work whose outcome is known beforehand. Every vehicle still decides with its own
`act`, and the road's rules are still highway-env's `enforce_road_rules`; what changes is how
the road and its lanes answer what those ask:

- act window: while the road's vehicles act (`Road.act`) nobody moves, turns or changes speed
  (checked after every `act`: a vehicle that does raises an error instead of going unnoticed).
  Meanwhile the network's lanes remember their `local_coordinates` answers (per position, by
  its bytes; highway-env's own method computes each once), and the remembering is removed when
  the vehicles are done.
- neighbours: a search asked while a plain `IDMVehicle` acts is answered from the lane's list
  of members, made once per window with highway-env's coordinates and `on_lane` test (vehicles
  that cannot be on a straight lane, by their coordinates in floats with a margin, are not
  projected) and sorted along the lane, so that the nearest ahead and behind are found by
  bisection, with highway-env's choice among equals. Every other vehicle's searches are
  highway-env's own (its code may show the road other vehicles for a moment, as
  `adversary.search.perceived_idm` does).
- collisions: pairs whose bounding circles cannot meet (highway-env's own first test, with a
  margin against rounding) are skipped; highway-env's `handle_collisions` runs for the others,
  in highway-env's order.
- closest lane: lanes are visited in the order of a lower bound of their distance and bounded
  from above in floats; only the lanes that may be the closest are measured by highway-env's own
  `distance_with_heading`, and the first smallest wins as in highway-env (`_LaneFinder`).
- right of way: during one `enforce_road_rules` each vehicle's trajectory is predicted once
  instead of once per pair (straight stretches with numpy's elementwise arithmetic, the
  arithmetic of `StraightLane.position`), the distances of all pairs at all predicted times come
  from one numpy computation, pairs that never come within the circle test's distance are
  answered at once, and rectangle tests whose answer is clear beyond rounding are not run
  (`_rectangles_known`; highway-env's `rotated_rectangles_intersect` answers the others). A pair
  the shortcuts cannot settle is left to highway-env's `is_conflict_possible` (`_RuleCheck`).
- outside highway-env, for a fast road: the recorder's route ahead is computed only when a scene
  asks for it, from copies of what it reads (`rasterize.highway._RouteLater`), with straight
  lanes sampled at once (`positions_along_route`), and so are the lanes of a scene
  (`rasterize.highway.lanes_near`); the smallest gap around the ego (`min_gap_on_road`) measures
  boxes nearest first while a lower bound can still beat the smallest gap found.

Nothing is approximated: every value that reaches a vehicle, a record or a scene is computed by
the same operations on the same numbers as before; floats only decide what need not be
computed, always with a margin far beyond rounding. `tests/riskmap/sim/test_fast_road.py`
drives the same seeds with and without the upgrade and requires equal states, crashes, gaps,
routes and scenes, and compares the neighbour searches and the right-of-way pair test with
highway-env's on random scenes.

Switch: `riskmap.sim.episode.make_env(env_id, fast=False)` builds a plain highway-env env, and
so does the environment variable RISKMAP_FAST_ROAD=0 for every env made without an explicit
`fast`. Only highway-env 1.12's `Road` and `RegulatedRoad` (exactly those classes) are upgraded,
since the shortcuts rely on what that version's methods compute; any other road is left as it is.
"""

from __future__ import annotations

import bisect
import functools
import math
import operator
import os

import numpy as np

ENV_VAR = "RISKMAP_FAST_ROAD"
SUPPORTED_HIGHWAY_ENV = "1.12."
_TOL_M = 1e-6            # margin on distances compared against a bound (m, or m + rad)
_TOL_REL = 1e-12         # relative margin, for distances far beyond metres


def fast_by_default() -> bool:
    """Whether envs are made fast when the caller does not say (RISKMAP_FAST_ROAD, default on)."""
    return os.environ.get(ENV_VAR, "1").strip().lower() not in ("0", "false", "no", "off")


def is_fast(road) -> bool:
    """Whether `road` is an upgraded road."""
    return bool(getattr(road, "fast_road", False))


def install(base_env) -> None:
    """Upgrade the road `base_env` (a highway-env env, unwrapped) has now and every road it builds
    on later resets, as soon as it is built (before the env places and warms up its traffic)."""
    for name in ("_make_road", "_create_road"):
        if callable(getattr(type(base_env), name, None)):
            setattr(base_env, name, functools.partial(_build_then_upgrade, base_env, name))
    if getattr(base_env, "road", None) is not None:
        upgrade_road(base_env.road)


def _build_then_upgrade(base_env, name: str, *args, **kwargs):
    result = getattr(type(base_env), name)(base_env, *args, **kwargs)
    if getattr(base_env, "road", None) is not None:
        upgrade_road(base_env.road)
    return result


def upgrade_road(road):
    """Turn `road` (a highway-env `Road` or `RegulatedRoad`, exactly) and its `RoadNetwork` into
    their fast subclasses, in place; anything else is left as it is. Returns `road`."""
    classes = _classes()
    if classes is None:
        return road
    if type(road) is classes["Road"]:
        road.__class__ = classes["FastRoad"]
    elif type(road) is classes["RegulatedRoad"]:
        road.__class__ = classes["FastRegulatedRoad"]
    else:
        return road
    if type(road.network) is classes["RoadNetwork"]:
        road.network.__class__ = classes["FastRoadNetwork"]
    return road


def __getattr__(name: str):
    # The classes subclass highway-env's, which is imported only once episodes run.
    classes = _classes() or {}
    if name in ("FastRoad", "FastRegulatedRoad", "FastRoadNetwork") and name in classes:
        return classes[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ---- lane bounds (closest lane) ---------------------------------------------------------------

def _lane_bounds(lane, straight, sine, circular) -> tuple[float, float, float, float, float] | None:
    """(xmin, xmax, ymin, ymax, slack) such that highway-env's `distance_with_heading` from any
    point to `lane` is at least the point's distance to the box less `slack`; None when unknown
    (such a lane is always measured).

    Straight: |lateral| + the overshoot beyond either end >= the Euclidean distance to the
    centre segment >= the distance to its box. Sine: its lateral is the straight one less at
    most |amplitude|. Circular: |radius - r| + the arc overshoot >= the distance to the arc
    (a chord is no longer than its arc) >= the distance to the circle's box. The heading term
    is never negative.
    """
    kind = type(lane)
    if kind is straight or kind is sine:
        start, end = np.asarray(lane.start, dtype=float), np.asarray(lane.end, dtype=float)
        slack = abs(float(lane.amplitude)) if kind is sine else 0.0
        ok = (start.shape == (2,) and end.shape == (2,) and np.isfinite(start).all()
              and np.isfinite(end).all() and np.isfinite(slack) and float(lane.length) > 0
              and np.isfinite(np.asarray(lane.direction, dtype=float)).all())
        if not ok:
            return None
        return (min(start[0], end[0]), max(start[0], end[0]), min(start[1], end[1]),
                max(start[1], end[1]), slack)
    if kind is circular:
        centre, radius = np.asarray(lane.center, dtype=float), float(lane.radius)
        if not (centre.shape == (2,) and np.isfinite(centre).all() and np.isfinite(radius)
                and radius > 0 and np.isfinite(float(lane.length))):
            return None
        return (centre[0] - radius, centre[0] + radius, centre[1] - radius, centre[1] + radius, 0.0)
    return None


def _wrap(x: float) -> float:
    return ((x + math.pi) % (2 * math.pi)) - math.pi


class _LaneFinder:
    """The closest-lane search over one network's lanes (`entries`: [(index, lane)] in the
    network's order), giving `RoadNetwork.get_closest_lane_index`'s answer.

    Lanes are visited in the order of a lower bound of their distance (the distance from the
    point, or with many lanes from its grid cell, to the lane's box, `_lane_bounds`), and
    approximated where the lane's formulas are known (straight and circular lanes; float
    arithmetic, within a rounding margin of highway-env's value: `_TOL_M` plus `_TOL_REL` of the
    coordinates involved); the visit stops at the first lane whose bound exceeds the smallest
    upper bound found. Only the lanes that may then be the closest are measured by highway-env's
    own `distance_with_heading`, and the first smallest of them is the answer, as in highway-env.

    It also holds the straight and circular lanes' geometry (`straight_lanes`,
    `circular_lanes`) for the act window's test of which vehicles may be on a lane.
    """

    CELL_M = 2.0
    FEW_LANES = 8

    def __init__(self, entries: list, straight, sine, circular):
        self.entries = entries
        self.bounds = [_lane_bounds(lane, straight, sine, circular) for _, lane in entries]
        self.params = [_approx_params(lane, straight, circular) for _, lane in entries]
        self.scales = [0.0 if p is None else 8 * sum(abs(v) for v in p[1:]) for p in self.params]
        self.cells: dict = {}
        # Straight lanes: start, direction, lateral direction, length and on_lane's limits.
        self.straight_lanes: dict = {}                # lane -> (sx, sy, d0, d1, l0, l1, length,
        for (_, lane), p in zip(entries, self.params):  # half width + 1, vehicle length)
            if p is not None and p[0] == "straight":
                try:
                    limits = (float(lane.width) / 2 + 1, float(lane.VEHICLE_LENGTH))
                except (TypeError, ValueError, AttributeError):
                    continue
                if all(map(math.isfinite, limits)):
                    self.straight_lanes[lane] = (*p[1:8], *limits)
        # Circular lanes: centre, radius and on_lane's lateral limit.
        self.circular_lanes: dict = {}                # lane -> (cx, cy, radius, half width + 1)
        for (_, lane), p in zip(entries, self.params):
            if p is not None and p[0] == "circular":
                try:
                    limit = float(lane.width) / 2 + 1
                except (TypeError, ValueError, AttributeError):
                    continue
                if math.isfinite(limit):
                    self.circular_lanes[lane] = (*p[1:4], limit)

    def _order(self, x0: float, y0: float, x1: float, y1: float) -> list:
        """[(lower bound, k)] sorted: a lower bound of the distance from any point of the box
        [x0, x1] x [y0, y1] to lane k."""
        order = []
        for k, b in enumerate(self.bounds):
            if b is None:
                order.append((-math.inf, k))
                continue
            xmin, xmax, ymin, ymax, slack = b
            gx = max(xmin - x1, x0 - xmax, 0.0)
            gy = max(ymin - y1, y0 - ymax, 0.0)
            order.append((math.hypot(gx, gy) - slack - _TOL_M, k))
        order.sort()
        return order

    def _cell(self, key: tuple[int, int]) -> list:
        x0, y0 = key[0] * self.CELL_M, key[1] * self.CELL_M
        order = self.cells[key] = self._order(x0, y0, x0 + self.CELL_M, y0 + self.CELL_M)
        return order

    def closest(self, position, heading):
        """The closest lane's index, or None where highway-env's own search must answer (a
        non-finite point or heading, or a lane measured as non-finite)."""
        try:
            x, y = float(position[0]), float(position[1])
            h = None if heading is None else float(heading)
        except (TypeError, IndexError, ValueError):
            return None
        if not (math.isfinite(x) and math.isfinite(y) and (h is None or math.isfinite(h))):
            return None
        if len(self.entries) <= self.FEW_LANES:             # bounds of the point itself
            order = self._order(x, y, x, y)
        else:                                               # cached bounds of its grid cell
            key = (math.floor(x / self.CELL_M), math.floor(y / self.CELL_M))
            order = self.cells.get(key) or self._cell(key)
        entries, params = self.entries, self.params
        upper, maybe, exact = math.inf, [], {}
        for lower, k in order:
            if lower > upper:
                break
            p = params[k]
            a = None if p is None else _approx_distance(p, x, y, h)
            if a is None:
                d = entries[k][1].distance_with_heading(position, heading)
                if not math.isfinite(d):
                    return None
                exact[k] = d
                maybe.append((k, d))
                upper = min(upper, d)
            else:
                e = _TOL_M + _TOL_REL * (abs(x) + abs(y) + self.scales[k])
                maybe.append((k, a - e))
                upper = min(upper, a + e)
        keep = sorted(k for k, low in maybe if low <= upper)
        if len(keep) == 1:
            return entries[keep[0]][0]
        distances = [exact[k] if k in exact else entries[k][1].distance_with_heading(position, heading)
                     for k in keep]
        if not all(math.isfinite(d) for d in distances):
            return None
        return entries[keep[_argmin(distances)]][0]


def _approx_params(lane, straight, circular):
    """What `_approx_distance` needs of a straight or circular lane; None for other lanes."""
    kind = type(lane)
    try:
        if kind is straight:
            values = (*map(float, lane.start), *map(float, lane.direction),
                      *map(float, lane.direction_lateral), float(lane.length), float(lane.heading))
            if len(values) == 8 and all(math.isfinite(v) for v in values) and values[6] > 0:
                return ("straight", *values)
        elif kind is circular:
            values = (*map(float, lane.center), float(lane.radius), float(lane.start_phase),
                      float(lane.direction), float(lane.length))
            if len(values) == 6 and all(math.isfinite(v) for v in values) and values[2] > 0:
                return ("circular", *values)
    except (TypeError, ValueError):
        return None
    return None


def _approx_distance(p, x: float, y: float, heading: float | None) -> float | None:
    """highway-env's `distance_with_heading` of a straight or circular lane, in floats (up to
    rounding); None near a circular lane's phase wrap, where rounding may jump."""
    if p[0] == "straight":
        _, sx, sy, d0, d1, l0, l1, length, lane_heading = p
        dx, dy = x - sx, y - sy
        s = dx * d0 + dy * d1
        r = dx * l0 + dy * l1
    else:
        _, cx, cy, radius, start, direction, length = p
        dx, dy = x - cx, y - cy
        w = _wrap(math.atan2(dy, dx) - start)
        if abs(w) > math.pi - 1e-6:
            return None
        s = direction * w * radius
        r = direction * (radius - math.hypot(dx, dy))
        lane_heading = direction * s / radius + start + math.pi / 2 * direction
    distance = abs(r) + max(s - length, 0.0) + max(0.0 - s, 0.0)
    if heading is not None:
        distance += abs(_wrap(heading - lane_heading))
    return distance


def _argmin(values: list) -> int:
    """`int(np.argmin(values))`: the first smallest, or the first NaN if there is one."""
    if any(math.isnan(v) for v in values):
        return int(np.argmin(values))
    best = 0
    for k in range(1, len(values)):
        if values[k] < values[best]:
            best = k
    return best


# ---- collisions ---------------------------------------------------------------------------------

def _collision_candidates(vehicles: list, members: list, dt: float) -> list | None:
    """(i, j) index pairs, in highway-env's order, whose collision check cannot be skipped: i a
    vehicle, j > i a vehicle or j >= len(vehicles) an object (`members` = vehicles + objects).
    None when the prefilter does not apply (then every pair is checked).

    highway-env's check returns at once when |p_j - p_i| > (diag_i + diag_j) / 2 + speed_i * dt;
    pairs are swept in the order of x, and a pair is kept unless that holds by more than a
    rounding margin."""
    n = len(vehicles)
    try:
        xy = [m.position.tolist() for m in members]
        diagonals = [float(m.diagonal) for m in members]
        speeds = [float(v.speed) for v in vehicles]
    except (AttributeError, TypeError, ValueError):
        return None
    if not all(len(p) == 2 and math.isfinite(p[0]) and math.isfinite(p[1]) for p in xy) or not (
            all(map(math.isfinite, diagonals)) and all(map(math.isfinite, speeds))):
        return None
    reach = max(diagonals) + max(0.0, max(speeds, default=0.0)) * dt
    order = sorted(range(len(members)), key=lambda k: xy[k][0])
    pairs = []
    for a, i in enumerate(order):
        xi = xy[i][0]
        for j in order[a + 1:]:
            if xy[j][0] - xi > reach + _TOL_M + _TOL_REL * abs(xi):
                break
            first, second = (i, j) if i < j else (j, i)
            if first >= n:
                continue                                  # two objects: never checked
            dx, dy = xy[second][0] - xy[first][0], xy[second][1] - xy[first][1]
            distance = math.hypot(dx, dy)
            threshold = (diagonals[first] + diagonals[second]) / 2 + speeds[first] * dt
            if distance > threshold + _TOL_M + _TOL_REL * (abs(xi) + abs(xy[i][1]) + distance):
                continue
            pairs.append((first, second))
    pairs.sort()
    return pairs


# ---- the act window: lane coordinates and neighbours --------------------------------------------

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


# ---- right of way -------------------------------------------------------------------------------

# The horizon and step `RegulatedRoad.enforce_road_rules` predicts over (is_conflict_possible's
# defaults; `_classes` checks them).
_HORIZON, _STEP = 3, 0.25


class _RuleCheck:
    """One `RegulatedRoad.enforce_road_rules` (highway-env's), which asks `is_conflict_possible`
    of every pair of the road's vehicles: is there a predicted time at which the two are within
    the first one's length (a circle test) and their boxes, scaled by 1.5 x 0.9, meet
    (`utils.rotated_rectangles_intersect`)? The answer is a function of the two predicted
    trajectories, and nobody moves during the check (checked at its end), so:

    - each vehicle's trajectory is predicted once (`predict` in `_classes`: the network's batch
      placement for highway-env's `ControlledVehicle` prediction, highway-env's own for
      `Vehicle`'s; vehicles with any other prediction are left to highway-env's function);
    - the distances of all pairs at all times come from one numpy computation; a time whose
      distance is beyond the circle test's limit by more than rounding is not examined, a pair
      with no other time is answered at once, and a pair with a time too near the limit to tell
      is left to highway-env's function;
    - at the other times the rectangles are built from the shared predictions, and tested by
      `_rectangles_known` where the answer is clear beyond rounding, else by highway-env's
      `rotated_rectangles_intersect`.
    """

    __slots__ = ("apart", "index", "intersect", "predict", "predictions", "snapshot",
                 "times_near", "unsure", "vehicles")

    def __init__(self, road, predict, intersect):
        self.vehicles = list(road.vehicles)
        self.index = {id(v): k for k, v in enumerate(self.vehicles)}
        self.snapshot = _states(self.vehicles)
        self.predict = predict        # vehicle -> (positions, headings), or None: not shared
        self.intersect = intersect    # highway-env's utils.rotated_rectangles_intersect
        self.predictions = None       # [k] -> (positions [T, 2], headings) or None
        self.apart = self.unsure = self.times_near = None

    def conflict(self, v1, v2) -> bool | None:
        """`is_conflict_possible(v1, v2)` (default horizon and step) as a bool, or None where
        highway-env's own function must answer."""
        a, b = self.index.get(id(v1)), self.index.get(id(v2))
        if a is None or b is None or self.vehicles[a] is not v1 or self.vehicles[b] is not v2:
            return None
        if self.predictions is None:
            self._prepare()
        if self.apart is None or self.predictions[a] is None or self.predictions[b] is None:
            return None
        if self.apart[a][b]:
            return False
        if self.unsure[a][b]:
            return None
        (positions_1, headings_1), (positions_2, headings_2) = self.predictions[a], self.predictions[b]
        size_1, size_2 = (1.5 * v1.LENGTH, 0.9 * v1.WIDTH), (1.5 * v2.LENGTH, 0.9 * v2.WIDTH)
        for t, distance in self.times_near[a, b]:
            rect_1 = (positions_1[t], *size_1, headings_1[t])
            rect_2 = (positions_2[t], *size_2, headings_2[t])
            overlap = _rectangles_known(rect_1, rect_2, distance)
            if overlap is None:
                overlap = self.intersect(rect_1, rect_2)
            if overlap:
                return True
        return False

    def _prepare(self) -> None:
        times = np.arange(_STEP, _HORIZON, _STEP)
        self.predictions = []
        for v in self.vehicles:
            try:
                prediction = self.predict(v, times)
            except Exception:          # noqa: BLE001 - highway-env's function raises it in turn
                prediction = None
            self.predictions.append(prediction)
        near = _near_in_time(self.vehicles, self.predictions)
        if near is not None:
            self.apart, self.unsure, self.times_near = near

    def unchanged(self) -> bool:
        """Whether nobody moved during the check."""
        return _states(self.vehicles) == self.snapshot


def _near_in_time(vehicles: list, predictions: list):
    """(apart, unsure, times_near) for every ordered pair (a, b) of vehicles with predictions of
    one length: `apart[a][b]` when at every time the distance exceeds a's length by more than
    rounding (the circle test fails throughout); `unsure[a][b]` when at some time it is too near
    that limit to tell; `times_near[a, b]` (read for the others) lists (t, distance) for the times
    at which it is below the limit beyond rounding. None when the predictions cannot be stacked
    (then highway-env's function answers every pair)."""
    rows = [k for k, p in enumerate(predictions) if p is not None]
    try:
        stacked = np.array([np.asarray(predictions[k][0], dtype=np.float64) for k in rows])
        headings = {len(predictions[k][1]) for k in rows}
        limits = np.array([float(v.LENGTH) for v in vehicles], dtype=np.float64)
    except (TypeError, ValueError, AttributeError):
        return None
    if not rows or stacked.ndim != 3 or stacked.shape[2] != 2 or headings != {stacked.shape[1]}:
        return None
    n = len(vehicles)
    delta = stacked[None, :, :, :] - stacked[:, None, :, :]
    distance = np.sqrt((delta * delta).sum(axis=-1))               # [i, j, time] over `rows`
    limit = limits[rows][:, None, None]
    tol = _TOL_M + _TOL_REL * distance
    far, near = distance > limit + tol, distance < limit - tol
    sub_apart, sub_unsure = far.all(axis=-1).tolist(), (~far & ~near).any(axis=-1).tolist()
    apart = [[False] * n for _ in range(n)]
    unsure = [[True] * n for _ in range(n)]
    for i, a in enumerate(rows):
        for j, b in enumerate(rows):
            apart[a][b], unsure[a][b] = sub_apart[i][j], sub_unsure[i][j]
    times_near = _TimesNear(rows, near, distance)
    return apart, unsure, times_near


class _TimesNear:
    """(t, distance) of the times at which a pair is within the circle test's limit, listed on
    first use."""

    __slots__ = ("distance", "found", "near", "position")

    def __init__(self, rows: list, near: np.ndarray, distance: np.ndarray):
        self.position = {k: i for i, k in enumerate(rows)}
        self.near, self.distance, self.found = near, distance, {}

    def __getitem__(self, pair: tuple[int, int]) -> list:
        found = self.found.get(pair)
        if found is None:
            i, j = self.position[pair[0]], self.position[pair[1]]
            times = np.flatnonzero(self.near[i, j]).tolist()
            found = self.found[pair] = [(t, float(self.distance[i, j, t])) for t in times]
        return found


def _rectangles_known(rect_1, rect_2, distance: float) -> bool | None:
    """What highway-env's `rotated_rectangles_intersect(rect_1, rect_2)` answers where that is
    clear beyond rounding, else None (then it must be asked).

    It tests whether one of the 9 points (corners, edge midpoints, centre) of either rectangle,
    placed at its angle, passes `point_in_rotated_rectangle` of the other, whose region is the
    other's box turned by minus its angle (the test rotates the offset by +angle). True: a centre
    lies in the other's inscribed circle (which no turn moves). False: each rectangle is apart
    from the other's region along one of their four axes."""
    try:
        (p1, l1, w1, h1), (p2, l2, w2, h2) = rect_1, rect_2
        l1, w1, h1, l2, w2, h2 = map(float, (l1, w1, h1, l2, w2, h2))
        dx, dy = float(p2[0]) - float(p1[0]), float(p2[1]) - float(p1[1])
    except (TypeError, ValueError, IndexError):
        return None
    if not all(map(math.isfinite, (l1, w1, h1, l2, w2, h2, dx, dy, distance))) \
            or min(l1, w1, l2, w2) <= 0:
        return None
    tol = _TOL_M + _TOL_REL * (abs(float(p1[0])) + abs(float(p1[1])) + l1 + l2)
    if distance < min(l1, w1, l2, w2) / 2 - tol:
        return True
    if _apart(dx, dy, l1, w1, h1, l2, w2, -h2, tol) and _apart(dx, dy, l2, w2, h2, l1, w1, -h1, tol):
        return False
    return None


def _apart(dx: float, dy: float, la: float, wa: float, ha: float, lb: float, wb: float,
           hb: float, tol: float) -> bool:
    """Whether boxes A (la x wa at angle ha) and B (lb x wb at angle hb), centres `(dx, dy)`
    apart, are separated by more than `tol` along one of their four axes."""
    ca, sa, cb, sb = math.cos(ha), math.sin(ha), math.cos(hb), math.sin(hb)
    cr, sr = abs(ca * cb + sa * sb), abs(sa * cb - ca * sb)        # |cos|, |sin| of ha - hb
    for ux, uy, half_a, half_b in ((ca, sa, la / 2, (lb * cr + wb * sr) / 2),
                                   (-sa, ca, wa / 2, (lb * sr + wb * cr) / 2),
                                   (cb, sb, (la * cr + wa * sr) / 2, lb / 2),
                                   (-sb, cb, (la * sr + wa * cr) / 2, wb / 2)):
        if abs(dx * ux + dy * uy) - half_a - half_b > tol:
            return True
    return False


# ---- the classes ------------------------------------------------------------------------------

_CLASSES: dict | None = None
_UNSUPPORTED = False


def _classes() -> dict | None:
    global _CLASSES, _UNSUPPORTED
    if _CLASSES is not None or _UNSUPPORTED:
        return _CLASSES
    import importlib.metadata
    import inspect

    from highway_env import utils
    from highway_env.road.lane import CircularLane, PolyLane, SineLane, StraightLane
    from highway_env.road.regulation import RegulatedRoad
    from highway_env.road.road import Road, RoadNetwork
    from highway_env.vehicle.behavior import IDMVehicle
    from highway_env.vehicle.controller import ControlledVehicle
    from highway_env.vehicle.kinematics import Vehicle
    from highway_env.vehicle.objects import Landmark, RoadObject

    try:
        version = importlib.metadata.version("highway-env")
    except importlib.metadata.PackageNotFoundError:
        version = ""
    if not version.startswith(SUPPORTED_HIGHWAY_ENV):
        _UNSUPPORTED = True
        return None

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

    for cls in (FastRoadNetwork, FastRoad, FastRegulatedRoad):
        cls.__module__ = __name__
        cls.__qualname__ = cls.__name__
    _CLASSES = {"Road": Road, "RegulatedRoad": RegulatedRoad, "RoadNetwork": RoadNetwork,
                "FastRoad": FastRoad, "FastRegulatedRoad": FastRegulatedRoad,
                "FastRoadNetwork": FastRoadNetwork}
    return _CLASSES


# ---- measurements -----------------------------------------------------------------------------

def min_gap_on_road(road, ego, radius_m: float) -> float:
    """`riskmap.sim.episode.min_gap_on_road`, the same value. Box gaps are measured in the order
    of a lower bound (the larger of the centre distance less both half diagonals and the boxes'
    separation along the ego's two axes), and only while that bound does not exceed the smallest
    gap found so far."""
    from riskmap.sim.metrics import box_gap, vehicle_box

    try:
        ex, ey = float(ego.position[0]), float(ego.position[1])
        heading, length, width = float(ego.heading), float(ego.LENGTH), float(ego.WIDTH)
        near = []
        for v in road.vehicles:
            if v is ego:
                continue
            dx, dy = float(v.position[0]) - ex, float(v.position[1]) - ey
            distance = math.hypot(dx, dy)
            margin = _TOL_M + _TOL_REL * (distance + abs(ex) + abs(ey))
            if not (distance < radius_m + margin):      # also NaN: measured the reference way
                if not math.isnan(distance):
                    continue
                return _min_gap_reference(road, ego, radius_m)
            if distance > radius_m - margin and not \
                    np.linalg.norm(v.position - ego.position) < radius_m:
                continue
            near.append((v, dx, dy, distance, margin))
    except (TypeError, ValueError, AttributeError, IndexError):
        return _min_gap_reference(road, ego, radius_m)
    if not near:
        return float("inf")
    c, s = math.cos(heading), math.sin(heading)
    bounded = []
    for v, dx, dy, distance, margin in near:
        l_v, w_v, relative = float(v.LENGTH), float(v.WIDTH), float(v.heading) - heading
        cos_r, sin_r = abs(math.cos(relative)), abs(math.sin(relative))
        # Separation along the ego's axes (two of the axes box_gap's overlap test tries).
        apart = max(abs(dx * c + dy * s) - 0.5 * (length + l_v * cos_r + w_v * sin_r),
                    abs(-dx * s + dy * c) - 0.5 * (width + l_v * sin_r + w_v * cos_r)) - margin
        lower = max(distance - 0.5 * math.hypot(l_v, w_v) - 0.5 * math.hypot(length, width)
                    - margin, apart)
        if not math.isfinite(lower):
            return _min_gap_reference(road, ego, radius_m)
        bounded.append((lower, apart > 0, v))
    box = vehicle_box(ego)
    best = float("inf")
    for lower, separated, v in sorted(bounded, key=lambda item: item[0]):
        if lower > best:
            break
        best = min(best, box_gap(box, vehicle_box(v), separated=separated))
    return float(best)


def _min_gap_reference(road, ego, radius_m: float) -> float:
    from riskmap.sim.metrics import min_box_gap, vehicle_box

    return min_box_gap(vehicle_box(ego), (vehicle_box(v) for v in road.vehicles
                                          if v is not ego and np.linalg.norm(v.position - ego.position) < radius_m))
