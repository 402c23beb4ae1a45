"""`idm` on recordings: IDM along the recorded vehicle's lanes, MOBIL for lane changes.

On a CommonRoad recording (`riskmap evaluate --commonroad --planners idm`) the rule-based
baseline drives the handed-over vehicle by the textbook models, on the lanelet network:

- Lane route. The lanelets the recorded vehicle occupies over its record (read once from its
  recorded positions) are the route; going forward from the ego's lanelet, a successor on the
  route is taken where there is one (a vehicle that took the off-ramp takes it), else the
  lowest-id successor. The route is only a choice among successors; the recorded speeds, times
  and lane changes are never used.
- Longitudinal: the Intelligent Driver Model (Treiber, Hennecke and Helbing 2000) towards a fixed
  freeway desired speed (`IdmMobilParams`; the recorded vehicle's own speeds would be future
  knowledge). The leader is the nearest vehicle ahead within half a lane width of the path,
  predicted at constant speed; IDM is integrated at 0.1 s over the 6 s horizon. During a lane
  change the ego also follows the target lane's leader, and the leader of the lane it leaves
  until its centre is out of that lane (the blended path alone loses a leader that the ego's
  front still overlaps); it takes the least of their accelerations. A change that MOBIL chose
  next to a stopped leader therefore waits for it: the path moves sideways with arc length.
- Lateral: MOBIL (Kesting, Treiber and Helbing 2007) between the ego's lanelet and its
  same-direction neighbours at every replan, from the present states only. A change blends the
  path from the ego's lateral offset to the target centre line (cosine over arc length, about
  3.5 s of driving) and stays committed across replans until the ego is near the target centre.
  Lane keeping uses the same blend, from the ego's offset to its own lane centre.
- Which neighbours MOBIL may choose: a lanelet on the recorded route, or one whose lane goes on
  beside the ego's lane at the next junction (a successor of it is a same-direction neighbour of
  a successor of the ego's lanelet; where the ego's lane ends, any neighbour). So MOBIL never
  moves onto a diverging ramp or a lane that ends while the ego's goes on; a lane that diverges
  further ahead is not looked for. There are no mandatory lane changes: an ego that MOBIL moved
  off the route's lane follows its own lane (on the NGSIM US-101 maps no lanelet branches).
- Off every lanelet the ego drives straight along its heading, with IDM on that line. Beyond
  the end of the mapped lanes the centre line runs straight on, so the plan is always finite.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.commonroad.route import _lanelet_under
from rasterize.commonroad.tracks import RecordedTraffic
from rasterize.errors import InputError
from rasterize.frames import ego_from_world
from rasterize.geometry import Polyline, drop_repeats
from rasterize.scene import Scene
from riskmap.sim.drivers.idm import idm_acceleration, idm_desired_gap
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS, Plan

HORIZON_S = PLAN_STEPS * PLAN_DT_S
PATH_STEP_M = 1.0          # spacing of the planned path's points


@dataclass(frozen=True)
class IdmMobilParams:
    """IDM and MOBIL parameters. Metres, seconds, m/s, m/s^2.

    The desired speed is a freeway value, not the recording's: NGSIM traffic runs at 7-19 m/s, so
    IDM is held back by its leaders, as the humans were."""

    desired_speed_mps: float = 30.0      # v0
    headway_s: float = 1.5               # T: desired time gap
    min_gap_m: float = 2.0               # s0: standstill gap, bumper to bumper
    max_accel_mps2: float = 1.5          # a
    comfort_decel_mps2: float = 2.0      # b
    delta: float = 4.0                   # free-road exponent
    max_decel_mps2: float = 6.0          # the hardest braking (the tracking controller's limit)
    politeness: float = 0.5              # p: weight of the followers' gains
    change_threshold_mps2: float = 0.2   # MOBIL's a_th: the least gain worth a lane change
    safe_decel_mps2: float = 4.0         # b_safe: no change that makes a follower brake harder
    lane_change_s: float = 3.5           # a lane change (and lane-keeping correction) lasts this
    min_lane_change_m: float = 15.0      # ... over at least this much road
    change_done_m: float = 0.3           # a change is over this close to the target centre
    behind_m: float = 60.0               # followers this far back count for MOBIL
    lane_width_m: float = 3.6            # off the lanelets: the width of the straight "lane"
    step_s: float = 0.1                  # IDM integration step

    def __post_init__(self) -> None:
        for name in ("desired_speed_mps", "headway_s", "max_accel_mps2", "comfort_decel_mps2",
                     "delta", "max_decel_mps2", "safe_decel_mps2", "lane_change_s",
                     "min_lane_change_m", "lane_width_m", "step_s"):
            if not getattr(self, name) > 0:
                raise InputError(f"IdmMobilParams.{name} must be positive")
        for name in ("min_gap_m", "politeness", "change_threshold_mps2", "change_done_m", "behind_m"):
            if not getattr(self, name) >= 0:
                raise InputError(f"IdmMobilParams.{name} must be >= 0")
        steps = PLAN_DT_S / self.step_s
        if abs(steps - round(steps)) > 1e-9:
            raise InputError("IdmMobilParams.step_s must divide the plan's 0.5 s step")


def idm_accel(speed: float, params: IdmMobilParams, gap: float | None = None,
              lead_speed: float = 0.0) -> float:
    """IDM acceleration (m/s^2) at `speed`, free road when `gap` (bumper to bumper, m) is None.

    a = a_max [1 - (v / v0)^delta - (s* / s)^2], s* = s0 + max(0, v T + v (v - v_lead) / (2 sqrt(a b))),
    bounded below by the hardest braking (IDM's own term is unbounded as the gap closes).
    The law is `riskmap.sim.drivers.idm`'s; a negative speed counts as 0 in the free-road term."""
    p = params
    desired = 0.0
    if gap is not None:
        desired = idm_desired_gap(speed, speed - lead_speed, min_gap_m=p.min_gap_m, headway_s=p.headway_s,
                                  max_accel_mps2=p.max_accel_mps2, comfort_decel_mps2=p.comfort_decel_mps2)
    return idm_acceleration(max(speed, 0.0), p.desired_speed_mps, max_accel_mps2=p.max_accel_mps2,
                            max_decel_mps2=p.max_decel_mps2, delta=p.delta, gap_m=gap, desired_gap_m=desired)


@dataclass(frozen=True)
class _Car:
    """A vehicle on a line: arc position of its centre (m), speed along the line, length."""

    arc_m: float
    speed_mps: float
    length_m: float


def _gap(back: _Car, front: _Car) -> float:
    return front.arc_m - back.arc_m - 0.5 * (front.length_m + back.length_m)


def _accel_behind(car: _Car, lead: _Car | None, params: IdmMobilParams) -> float:
    """IDM acceleration of `car` following `lead` (free road without one)."""
    if lead is None:
        return idm_accel(car.speed_mps, params)
    return idm_accel(car.speed_mps, params, _gap(car, lead), lead.speed_mps)


def idm_distances(speed: float, length_m: float, leaders: list[_Car],
                  params: IdmMobilParams) -> np.ndarray:
    """Distances (m) along the path at the plan's 12 times, IDM integrated every `step_s` from arc
    0 (where the ego is) behind leaders driving on at constant speed: the least acceleration of
    those it follows (free road without any)."""
    per_plan_step = round(PLAN_DT_S / params.step_s)
    me = _Car(0.0, max(float(speed), 0.0), length_m)
    out = []
    for k in range(PLAN_STEPS * per_plan_step):
        ahead = [_Car(lead.arc_m + lead.speed_mps * k * params.step_s, lead.speed_mps, lead.length_m)
                 for lead in leaders]
        accel = min((_accel_behind(me, lead, params) for lead in ahead),
                    default=_accel_behind(me, None, params))
        new_speed = max(0.0, me.speed_mps + accel * params.step_s)
        me = _Car(me.arc_m + 0.5 * (me.speed_mps + new_speed) * params.step_s, new_speed, length_m)
        if (k + 1) % per_plan_step == 0:
            out.append(me.arc_m)
    return np.array(out)


# --- geometry ------------------------------------------------------------------------------------

def _line(points: np.ndarray) -> Polyline:
    """The line through `points` [K, 2] without repeated points; past either end it runs straight
    on along the end segment (`Polyline.pose_at`, `Polyline.project`), so positions beyond the
    mapped lanes stay finite."""
    return Polyline(drop_repeats(np.asarray(points, dtype=np.float64)))


def _left_normal(tangent: np.ndarray) -> np.ndarray:
    return np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)


def _cosine_blend(q: np.ndarray) -> np.ndarray:
    """0 at q = 0 to 1 at q = 1 with zero slope at both ends."""
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(q, 0.0, 1.0))


def _blend_progress(remaining: float) -> float:
    """The q at which a cosine blend has `remaining` (0..1) of its offset left."""
    return float(np.arccos(np.clip(2.0 * remaining - 1.0, -1.0, 1.0)) / np.pi)


# --- lanelets ------------------------------------------------------------------------------------

def _same_direction_neighbours(lanelet) -> list[tuple[int, int]]:
    """(side: +1 left / -1 right, lanelet id) of the same-direction neighbours."""
    out = []
    if lanelet.adj_left is not None and lanelet.adj_left_same_direction:
        out.append((1, int(lanelet.adj_left)))
    if lanelet.adj_right is not None and lanelet.adj_right_same_direction:
        out.append((-1, int(lanelet.adj_right)))
    return out


def recorded_lanelets(traffic: RecordedTraffic, agent: int) -> tuple[int, ...]:
    """The lanelet ids agent index `agent` occupies over its record, in order, without repeats."""
    network = traffic.scenario.lanelet_network
    first, last = traffic.span(agent)
    ids: list[int] = []
    for step in range(first, last + 1):
        lanelet = _lanelet_under(network, traffic.states[agent, step])
        if lanelet is not None and (not ids or ids[-1] != lanelet.lanelet_id):
            ids.append(int(lanelet.lanelet_id))
    return tuple(ids)


class LaneRoute:
    """Successor / predecessor choice on a lanelet network: the route's lanelets first, else the
    lowest id."""

    def __init__(self, network, lanelet_ids: tuple[int, ...]):
        self.network, self.ids, self.members = network, tuple(lanelet_ids), frozenset(lanelet_ids)

    def _pick(self, candidates) -> object | None:
        candidates = [int(c) for c in candidates]
        if not candidates:
            return None
        on_route = [c for c in candidates if c in self.members]
        return self.network.find_lanelet_by_id(min(on_route or candidates))

    def next(self, lanelet):
        return self._pick(lanelet.successor)

    def previous(self, lanelet):
        return self._pick(lanelet.predecessor)

    def centre_line(self, lanelet, ahead_m: float, behind_m: float) -> Polyline:
        """The lane's centre line through `lanelet`: predecessors for `behind_m`, successors for
        `ahead_m` beyond it (each along the route choice)."""
        parts = [np.asarray(lanelet.center_vertices, dtype=np.float64)]
        for step, budget, prepend in ((self.previous, behind_m, True), (self.next, ahead_m, False)):
            current, total, seen = lanelet, 0.0, {lanelet.lanelet_id}
            while total < budget:
                current = step(current)
                if current is None or current.lanelet_id in seen:
                    break
                seen.add(current.lanelet_id)
                centre = np.asarray(current.center_vertices, dtype=np.float64)
                if prepend:
                    parts.insert(0, centre)
                else:
                    parts.append(centre)
                total += float(np.linalg.norm(np.diff(centre, axis=0), axis=1).sum())
        return _line(np.concatenate(parts))

    def may_change_to(self, lanelet, neighbour) -> bool:
        """Whether MOBIL may move from `lanelet` onto its neighbour (module docstring): on the
        route, or the neighbour's lane goes on beside this one at the next junction."""
        if int(neighbour.lanelet_id) in self.members or not lanelet.successor:
            return True
        mine = {int(s) for s in lanelet.successor}
        for successor in neighbour.successor:
            beside = self.network.find_lanelet_by_id(successor)
            if any(i in mine for _, i in _same_direction_neighbours(beside)):
                return True
        return False

    def reachable(self, lanelet) -> frozenset[int]:
        """`lanelet` and every lanelet after it: one lane, for a committed change."""
        out, todo = set(), [int(lanelet.lanelet_id)]
        while todo:
            lanelet_id = todo.pop()
            if lanelet_id not in out:
                out.add(lanelet_id)
                todo += [int(s) for s in self.network.find_lanelet_by_id(lanelet_id).successor]
        return frozenset(out)


def _width(lanelet) -> float:
    return float(np.linalg.norm(np.asarray(lanelet.left_vertices) - np.asarray(lanelet.right_vertices),
                                axis=1).mean())


# --- the planner ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Others:
    """The other vehicles present now: states [M, 6] (world), lengths [M]."""

    states: np.ndarray
    lengths: np.ndarray

    @classmethod
    def of(cls, scene: Scene) -> _Others:
        now = scene.current_index
        keep = np.flatnonzero(scene.valid[:, now])
        keep = keep[keep != scene.ego_index]
        return cls(scene.states[keep, now], scene.sizes[keep, 0])

    def leader_on(self, line: Polyline, half_width_m: float, ego_xy: np.ndarray) -> _Car | None:
        """The nearest vehicle ahead of the ego on `line`, its arc measured from the ego's."""
        ego_arc = float(line.project(ego_xy)[0][0])
        ahead = [c for c in self.on(line, half_width_m) if c.arc_m > ego_arc]
        lead = min(ahead, key=lambda c: c.arc_m, default=None)
        return None if lead is None else _Car(lead.arc_m - ego_arc, lead.speed_mps, lead.length_m)

    def on(self, line: Polyline, half_width_m: float) -> list[_Car]:
        """The vehicles within `half_width_m` of `line`, as cars on it (speed along it)."""
        if not len(self.states):
            return []
        arc, lateral = line.project(self.states[:, :2])
        _, tangent = line.pose_at(arc)
        speed = self.states[:, 4] * np.einsum("md,md->m", self.states[:, 2:4], tangent)
        return [_Car(float(arc[i]), max(0.0, float(speed[i])), float(self.lengths[i]))
                for i in np.flatnonzero(np.abs(lateral) <= half_width_m)]


@dataclass(frozen=True)
class _Queue:
    """The ego and its leader and follower in one lane (arc positions on that lane's line)."""

    me: _Car
    leader: _Car | None
    follower: _Car | None

    @classmethod
    def of(cls, me: _Car, cars: list[_Car], behind_m: float) -> _Queue:
        ahead = [c for c in cars if c.arc_m > me.arc_m]
        behind = [c for c in cars if me.arc_m - behind_m <= c.arc_m <= me.arc_m]
        return cls(me, min(ahead, key=lambda c: c.arc_m, default=None),
                   max(behind, key=lambda c: c.arc_m, default=None))


def mobil_gain(here: _Queue, there: _Queue, params: IdmMobilParams) -> float | None:
    """MOBIL's incentive (m/s^2) to move from lane `here` to lane `there`; None when unsafe (the
    ego would overlap someone, or it or the new follower would brake harder than b_safe)."""
    p = params
    if (there.leader is not None and _gap(there.me, there.leader) <= 0.0) or (
            there.follower is not None and _gap(there.follower, there.me) <= 0.0):
        return None
    mine = _accel_behind(there.me, there.leader, p)
    if mine < -p.safe_decel_mps2:
        return None
    others = 0.0
    if there.follower is not None:
        after = _accel_behind(there.follower, there.me, p)
        if after < -p.safe_decel_mps2:
            return None
        others += after - _accel_behind(there.follower, there.leader, p)
    if here.follower is not None:
        others += _accel_behind(here.follower, here.leader, p) - _accel_behind(here.follower, here.me, p)
    return mine - _accel_behind(here.me, here.leader, p) + p.politeness * others


@dataclass(frozen=True)
class _LaneChange:
    """A committed lane change: the target lane (its lanelets), the side, the ego's lateral
    offset from the target centre when it began, and the blend's length."""

    lanes: frozenset[int]
    side: int
    start_offset_m: float
    length_m: float


class RecordedRouteIdmPlanner:
    """`idm` on recordings: IDM + MOBIL along the recorded vehicle's lanes (module docstring)."""

    def __init__(self, traffic: RecordedTraffic, obstacle_id: int,
                 params: IdmMobilParams = IdmMobilParams()):
        self.network, self.params = traffic.scenario.lanelet_network, params
        self.route = LaneRoute(self.network, recorded_lanelets(traffic, traffic.index_of(obstacle_id)))
        self._change: _LaneChange | None = None

    def reset(self, scene: Scene) -> None:
        self._change = None

    def plan(self, scene: Scene) -> Plan:
        ego = scene.ego_state()
        length = float(scene.sizes[scene.ego_index, 0])
        others = _Others.of(scene)
        path, watched = self._path(ego, length, others)
        leaders = [lead for line, half_width in watched
                   if (lead := others.leader_on(line, half_width, ego[:2])) is not None]
        xy, _ = path.pose_at(idm_distances(float(ego[4]), length, leaders, self.params))
        return Plan(ego_from_world(xy, ego[:2], float(np.arctan2(ego[3], ego[2]))))

    def _reach(self, speed: float) -> float:
        """Path length (m) that covers any IDM distance over the horizon."""
        top = max(speed, self.params.desired_speed_mps)
        return top * HORIZON_S + 0.5 * self.params.max_accel_mps2 * HORIZON_S ** 2 + 10.0

    def _blend_length(self, speed: float) -> float:
        return max(self.params.min_lane_change_m, speed * self.params.lane_change_s)

    def _path(self, ego: np.ndarray, length: float,
              others: _Others) -> tuple[Polyline, list[tuple[Polyline, float]]]:
        """The path ahead of the ego (from where it is), and the lines (with half their lane's
        width) whose leaders it follows: the path; during a change also the target lane, and the
        lane it leaves until its centre is out of it (the blended path alone would lose a leader
        there that the ego's front still overlaps)."""
        reach = self._reach(float(ego[4]))
        lanelet = _lanelet_under(self.network, ego)
        if lanelet is None:
            self._change = None
            path = _line(np.stack([ego[:2], ego[:2] + reach * ego[2:4]]))
            return path, [(path, 0.5 * self.params.lane_width_m)]
        target = self._committed_target(lanelet)
        if target is None:
            target = self._mobil(lanelet, ego, length, others, reach)
        line = self.route.centre_line(target, reach, self.params.behind_m)
        path = self._blended(line, ego, reach)
        watched = [(path, 0.5 * _width(target))]
        if self._change is not None:
            watched.append((line, 0.5 * _width(target)))
            if target.lanelet_id != lanelet.lanelet_id:
                watched.append((self.route.centre_line(lanelet, reach, self.params.behind_m),
                                0.5 * _width(lanelet)))
        return path, watched

    def _committed_target(self, lanelet):
        """The lanelet of the committed change beside (or under) the ego, or None (no change, or
        the ego is no longer next to its target lane: the change is dropped)."""
        change = self._change
        if change is None:
            return None
        if int(lanelet.lanelet_id) in change.lanes:
            return lanelet
        beside = dict(_same_direction_neighbours(lanelet)).get(change.side)
        if beside is None or beside not in change.lanes:
            self._change = None
            return None
        return self.network.find_lanelet_by_id(beside)

    def _mobil(self, lanelet, ego: np.ndarray, length: float, others: _Others, reach: float):
        """The lanelet MOBIL chooses (the ego's own unless a change pays); commits a change."""
        p, speed = self.params, float(ego[4])
        here = self._queue(lanelet, ego, length, others, reach)
        best, best_gain, chosen = lanelet, p.change_threshold_mps2, None
        for side, neighbour_id in _same_direction_neighbours(lanelet):
            neighbour = self.network.find_lanelet_by_id(neighbour_id)
            if not self.route.may_change_to(lanelet, neighbour):
                continue
            there = self._queue(neighbour, ego, length, others, reach)
            gain = mobil_gain(here, there, p)
            if gain is not None and gain > best_gain:
                best, best_gain, chosen = neighbour, gain, side
        if chosen is not None:
            line = self.route.centre_line(best, reach, p.behind_m)
            offset = float(line.project(ego[:2])[1][0])
            self._change = _LaneChange(self.route.reachable(best), chosen, offset,
                                       self._blend_length(speed))
        return best

    def _queue(self, lanelet, ego: np.ndarray, length: float, others: _Others, reach: float) -> _Queue:
        line = self.route.centre_line(lanelet, reach, self.params.behind_m)
        arc, _ = line.project(ego[:2])
        _, tangent = line.pose_at(arc)
        me = _Car(float(arc[0]), max(0.0, float(ego[4] * np.dot(ego[2:4], tangent[0]))), length)
        return _Queue.of(me, others.on(line, 0.5 * _width(lanelet)), self.params.behind_m)

    def _blended(self, line: Polyline, ego: np.ndarray, reach: float) -> Polyline:
        """The path from the ego onto `line`: its lateral offset fades out (cosine over arc length)
        along a committed change's remaining blend, or a lane-keeping one."""
        arc, lateral = line.project(ego[:2])
        offset = float(lateral[0])
        change = self._change
        if change is not None and abs(offset) < self.params.change_done_m:
            self._change = change = None                  # arrived: keep the lane from here
        ratio = offset / change.start_offset_m if change is not None and change.start_offset_m else -1.0
        if 0.0 < ratio <= 1.0:
            start, progress, length = change.start_offset_m, _blend_progress(ratio), change.length_m
        else:
            start, progress, length = offset, 0.0, self._blend_length(float(ego[4]))
        ds = np.arange(0.0, reach + PATH_STEP_M, PATH_STEP_M)
        xy, tangent = line.pose_at(arc[0] + ds)
        fade = start * (1.0 - _cosine_blend(progress + ds / length))
        return _line(xy + fade[:, None] * _left_normal(tangent))
