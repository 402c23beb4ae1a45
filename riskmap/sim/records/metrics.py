"""Every driving and safety metric of the toolkit, each defined once.

States are world-frame rows (x, y, heading_x, heading_y, speed, yaw_rate); sizes are (length,
width) in metres; a box is its corners [4, 2] (`rasterize.frames.box_corners`). Functions named
for highway-env vehicles (`vehicle_box`, `centre_off_lane`, `closing_dangerous_encounters`,
`coarse_collision_type`) read only the attributes they name (position, heading, velocity,
LENGTH, WIDTH, road.network), so this module does not import highway-env.

Trajectory metrics (benchmark, planner paper Table I); trajectories [T, 2] m every `dt_s` s:
- ade_m: mean distance between ego and human at equal times (an ego that ended early stays put).
- goal_error_m: distance between the two end points.
- path_length_m: length of the driven polyline.
- mean_jerk_mps3: mean |third finite difference of position| / dt^3 (0 with < 4 points).

Traffic lights:
- stop_line_crossings: times at which a vehicle's front (its centre plus half its length along
  its heading) crosses a stop line forwards (from behind it to beyond it, in the lane's
  direction, within the line's two ends, heading within 60 degrees of the lane's). A red-light
  violation is such a crossing while the light governing the vehicle's turn is red (amber
  counts as red), counted once per crossing (`riskmap.sim.worlds.commonroad_replay.red_light_events`).

Box geometry:
- box_gap (from rasterize.geometry): clearance between two boxes, 0 when they touch or overlap.
- min_box_gap: smallest box_gap from one box to several (inf when there are none).
- box_iou: intersection over union of two boxes' areas (shapely), 0 without an intersection.

Safety % (two readings of the planner paper's "share of encounters in which the ego is
dangerously close"; both appear in reports, under different names):
- dangerous_encounters / SafetyConfig (planner benchmark): every step, every ado whose centre is
  nearer than `encounter_radius_m` (30 m) is an encounter; dangerous when the box gap is under
  `close_gap_m` (1.0 m) or the boxes, each moving on at constant velocity, overlap within `ttc_s`
  (1.5 s, checked every `ttc_step_s` = 0.1 s). Vehicles passing in adjacent lanes never count.
- closing_dangerous_encounters / ClosingSafetyConfig (stress-test campaigns): every vehicle whose
  centre is at most `radius_m` (40 m) away is an encounter; dangerous when the box gap is under
  `close_gap_m` (2.0 m) or gap / closing speed along the line of centres (when closing) is under
  `ttc_s` (1.5 s). Wider and more cautious: a neighbour drifting towards the ego counts.
- safety_pct: 100 * dangerous / encounters (0 without encounters).

Collision (STRIVE as CRASH uses it; `StriveConfig`):
- a collision is a box IoU above `collision_iou` (0.02).
- classify_collision (fine, 6 classes COLLISION_TYPES): from dpsi (adversary heading relative to
  the ego's) and its centre in the ego's frame: head-on |dpsi| > 120 deg; T-bone 60..120 deg;
  cut-in (ahead, and beside the ego's path earlier in the track); ego rear-ends / rear-ended
  (longitudinal penetration <= lateral); else side-swipe.
- coarse_collision_type (campaign monitor, highway-env's crash flag; 5 classes): head-on
  |dpsi| >= 150 deg; |dpsi| <= 30 deg: rear-end when laterally overlapping, else sideswipe;
  anything else side (angle). Its thresholds differ from classify_collision's, so it is a second
  classifier, not a relabelling.
- coarse_collision_name / COARSE_COLLISION_NAMES: classify_collision's labels in the campaign's
  vocabulary (side-swipe -> sideswipe, T-bone -> side (angle); cut-in keeps its name), so that
  campaign records from both sources share CAMPAIGN_COLLISION_TYPES.

Off-road (two readings):
- off_road_fraction (STRIVE): share of the box's area outside the union of the lane polygons
  (`drivable_area`); box_off_road: above `StriveConfig.off_road_fraction` (0.05).
- centre_off_lane (simulation): the vehicle's centre is more than `margin_m` outside the lane of
  the road network nearest to it (past the end of the road or off it sideways).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from rasterize.frames import box_corners
from rasterize.geometry import box_gap, boxes_overlap

__all__ = [
    "CAMPAIGN_COLLISION_TYPES", "COARSE_COLLISION_NAMES", "COLLISION_TYPES", "STRIVE", "ClosingSafetyConfig",
    "SafetyConfig", "StriveConfig", "ade_m", "box_gap", "box_iou", "box_off_road", "box_polygon",
    "centre_off_lane", "classify_collision", "lane_width_at", "closing_dangerous_encounters", "coarse_collision_name",
    "coarse_collision_type", "dangerous_encounters", "drivable_area", "goal_error_m", "in_frame", "mean_jerk_mps3",
    "min_box_gap", "off_road_fraction", "on_network", "overlap_within", "path_length_m", "safety_pct", "stop_line_crossings",
    "summarise_metric", "vehicle_box",
]


@dataclass(frozen=True)
class SafetyConfig:
    """Safety % of the planner benchmark (`dangerous_encounters`)."""

    encounter_radius_m: float = 30.0   # ado centres nearer than this are neighbours
    close_gap_m: float = 1.0           # box clearance below this is dangerously close
    ttc_s: float = 1.5                 # time to collision below this is dangerously close
    ttc_step_s: float = 0.1            # time resolution of the constant-velocity check


@dataclass(frozen=True)
class ClosingSafetyConfig:
    """Safety % and off-road margin of stress-test campaigns (`closing_dangerous_encounters`,
    `centre_off_lane`); a campaign config's `safety:` block sets these fields."""

    close_gap_m: float = 2.0           # box clearance below this is dangerously close
    ttc_s: float = 1.5                 # gap / closing speed below this is dangerously close
    radius_m: float = 40.0             # vehicles whose centre is at most this far are encounters
    off_road_margin_m: float = 1.0     # centre beyond the nearest lane's edge by this = off-road


@dataclass(frozen=True)
class StriveConfig:
    """STRIVE's thresholds as CRASH's judge applies them."""

    collision_iou: float = 0.02        # box IoU (area ratio) above this is a collision
    off_road_fraction: float = 0.05    # share of the box's area off the lanes above this is off-road


STRIVE = StriveConfig()


# ---- trajectories ---------------------------------------------------------------------------

def ade_m(ego_xy: np.ndarray, human_xy: np.ndarray) -> float:
    """Mean distance between the two trajectories at equal times, over the human's steps.

    An ego trajectory that ended early (the ego crashed or left the road, which ends the episode)
    stays at its last position for the rest: leaving early must not shorten the comparison.
    """
    ego_xy, human_xy = np.asarray(ego_xy, float), np.asarray(human_xy, float)
    if len(ego_xy) < len(human_xy):
        ego_xy = np.concatenate([ego_xy, np.repeat(ego_xy[-1:], len(human_xy) - len(ego_xy), axis=0)])
    return float(np.linalg.norm(ego_xy[: len(human_xy)] - human_xy, axis=1).mean())


def goal_error_m(ego_xy: np.ndarray, human_xy: np.ndarray) -> float:
    """Distance from where the ego ended to where the human ended (its goal)."""
    return float(np.linalg.norm(np.asarray(ego_xy[-1], float) - np.asarray(human_xy[-1], float)))


def path_length_m(xy: np.ndarray) -> float:
    """Distance driven: the length of the polyline."""
    return float(np.linalg.norm(np.diff(np.asarray(xy, float), axis=0), axis=1).sum())


def mean_jerk_mps3(xy: np.ndarray, dt_s: float) -> float:
    """Mean magnitude of the third time derivative of position (finite differences); 0 if < 4 points."""
    xy = np.asarray(xy, float)
    if len(xy) < 4:
        return 0.0
    jerk = np.diff(xy, n=3, axis=0) / dt_s ** 3
    return float(np.linalg.norm(jerk, axis=1).mean())


# ---- traffic lights -------------------------------------------------------------------------

def stop_line_crossings(times_s: np.ndarray, states: np.ndarray, length_m: float,
                        stop_line: np.ndarray, forward: np.ndarray,
                        max_angle_deg: float = 60.0) -> list[float]:
    """Times (s) at which the vehicle's front crosses `stop_line` forwards (module docstring).

    times_s [T] increasing; states [T, >=4] world (x, y, heading_x, heading_y, ...); stop_line
    [2, 2] its two ends; forward [2] the lane's driving direction at the line. The crossing time
    is interpolated between the two steps around it. A front that starts beyond the line, or
    goes back behind it and crosses again, counts per forward crossing.
    """
    times_s, states = np.asarray(times_s, float), np.asarray(states, float)
    if len(times_s) < 2:
        return []
    line = np.asarray(stop_line, float)
    forward = np.asarray(forward, float) / max(float(np.linalg.norm(forward)), 1e-12)
    along_line = line[1] - line[0]
    span = float(np.dot(along_line, along_line))
    front = states[:, :2] + 0.5 * float(length_m) * states[:, 2:4]
    # Signed distance from the line (positive beyond it, on the side `forward` points to).
    normal = np.array([-along_line[1], along_line[0]]) / max(np.sqrt(span), 1e-12)
    normal = normal if float(np.dot(normal, forward)) >= 0 else -normal
    ahead = (front - line[0]) @ normal
    out = []
    for k in np.flatnonzero((ahead[:-1] < 0) & (ahead[1:] >= 0)):
        alpha = float(-ahead[k] / (ahead[k + 1] - ahead[k]))
        point = front[k] + alpha * (front[k + 1] - front[k])
        u = float(np.dot(point - line[0], along_line) / max(span, 1e-12))
        if not 0.0 <= u <= 1.0:
            continue                                         # beside the line: another lane's
        if float(np.dot(states[k + 1, 2:4], forward)) < np.cos(np.radians(max_angle_deg)):
            continue                                         # across the lane, not along it
        out.append(float(times_s[k] + alpha * (times_s[k + 1] - times_s[k])))
    return out


# ---- box geometry ---------------------------------------------------------------------------

def vehicle_box(vehicle) -> np.ndarray:
    """Corners [4, 2] of a highway-env vehicle's box, in highway-env's frame (gaps and overlaps
    do not depend on the frame's handedness)."""
    return box_corners(vehicle.position, [np.cos(vehicle.heading), np.sin(vehicle.heading)],
                       vehicle.LENGTH, vehicle.WIDTH)


def min_box_gap(box: np.ndarray, others: Iterable[np.ndarray]) -> float:
    """Smallest `box_gap` (m) from `box` to any of `others` (corners [4, 2] each); inf if none."""
    return float(min((box_gap(box, other) for other in others), default=float("inf")))


def box_polygon(state: np.ndarray, size: np.ndarray):
    """The shapely polygon of a vehicle box: state [>=4] (x, y, heading_x, heading_y), size (l, w)."""
    from shapely.geometry import Polygon

    return Polygon(box_corners(state[:2], state[2:4], float(size[0]), float(size[1])))


def box_iou(state_a: np.ndarray, size_a: np.ndarray, state_b: np.ndarray, size_b: np.ndarray) -> float:
    """Intersection over union of two vehicle boxes' areas (0 when they do not intersect)."""
    a, b = box_polygon(state_a, size_a), box_polygon(state_b, size_b)
    inter = a.intersection(b).area
    return float(inter / (a.area + b.area - inter)) if inter > 0 else 0.0


# ---- Safety % -------------------------------------------------------------------------------

def dangerous_encounters(ego: np.ndarray, ego_size: np.ndarray, others: np.ndarray,
                         others_valid: np.ndarray, others_sizes: np.ndarray,
                         config: SafetyConfig = SafetyConfig()) -> tuple[int, int]:
    """(dangerous encounters, encounters) over an episode, planner-benchmark reading (module
    docstring).

    ego [T, 6] states (x, y, heading_x, heading_y, speed, yaw_rate); others [N, T, 6] with
    validity [N, T]; sizes (length, width) in metres.
    """
    dangerous = total = 0
    for t in range(ego.shape[0]):
        p, h, v = ego[t, :2], ego[t, 2:4], ego[t, 4]
        near = np.flatnonzero(others_valid[:, t] &
                              (np.linalg.norm(others[:, t, :2] - p, axis=1) < config.encounter_radius_m))
        if near.size == 0:
            continue
        me = box_corners(p, h, ego_size[0], ego_size[1])
        for a in near:
            q, g, w = others[a, t, :2], others[a, t, 2:4], others[a, t, 4]
            total += 1
            them = box_corners(q, g, others_sizes[a, 0], others_sizes[a, 1])
            if box_gap(me, them) < config.close_gap_m or overlap_within(
                    me, v * h, them, w * g, config.ttc_s, config.ttc_step_s):
                dangerous += 1
    return dangerous, total


def overlap_within(a: np.ndarray, velocity_a: np.ndarray, b: np.ndarray, velocity_b: np.ndarray,
                    horizon_s: float, step_s: float) -> bool:
    """Whether boxes a and b (corners [4, 2]) overlap at some time in (0, horizon] at constant velocity."""
    relative = np.asarray(velocity_b, float) - np.asarray(velocity_a, float)
    reach = 0.5 * (np.ptp(a, axis=0).sum() + np.ptp(b, axis=0).sum())   # > sum of half-diagonals
    offset = b.mean(axis=0) - a.mean(axis=0)
    for t in np.arange(1, round(horizon_s / step_s) + 1) * step_s:
        if np.linalg.norm(offset + t * relative) <= reach and boxes_overlap(a, b + t * relative):
            return True
    return False


def closing_dangerous_encounters(ego, vehicles: Iterable, config: ClosingSafetyConfig = ClosingSafetyConfig()
                                 ) -> tuple[int, int]:
    """(dangerous encounters, encounters) at one step, campaign reading (module docstring).

    ego and vehicles are highway-env vehicles (position, velocity, heading, LENGTH, WIDTH);
    the ego itself may be among `vehicles`.
    """
    mine = vehicle_box(ego)
    dangerous = total = 0
    for other in vehicles:
        d = other.position - ego.position
        dist = float(np.linalg.norm(d))
        if other is ego or dist > config.radius_m:
            continue
        gap = box_gap(mine, vehicle_box(other))
        closing = -float(np.dot(other.velocity - ego.velocity, d)) / max(dist, 1e-9)
        ttc = gap / closing if closing > 1e-9 else np.inf   # moving apart never collides
        total += 1
        dangerous += int(gap < config.close_gap_m or ttc < config.ttc_s)
    return dangerous, total


def safety_pct(dangerous: int, encounters: int) -> float:
    """Share of encounters that were dangerous, in percent (0 when there were none)."""
    return 100.0 * dangerous / encounters if encounters else 0.0


# ---- off-road -------------------------------------------------------------------------------

def drivable_area(lanes):
    """Union of the lanes' polygons (shapely); curved lanes whose outline crosses itself are
    repaired first."""
    from shapely import make_valid, unary_union
    from shapely.geometry import Polygon

    return unary_union([make_valid(Polygon(lane.polygon())) for lane in lanes])


def off_road_fraction(state: np.ndarray, size: np.ndarray, area) -> float:
    """Share of the box's area outside the drivable `area` (0 on the road, 1 fully off)."""
    box = box_polygon(state, size)
    outside = float(1.0 - box.intersection(area).area / box.area)
    return outside if outside > 1e-9 else 0.0      # no rounding noise for boxes on the road


def box_off_road(state: np.ndarray, size: np.ndarray, area, config: StriveConfig = STRIVE) -> bool:
    """STRIVE's off-road: more than `config.off_road_fraction` of the box outside `area`."""
    return off_road_fraction(state, size, area) > config.off_road_fraction


def centre_off_lane(road, vehicle, margin_m: float = 1.0) -> bool:
    """True once the vehicle's centre is off every lane (past the end of the road, or off it
    sideways by more than `margin_m`).

    highway-env's own `on_road` checks only the vehicle's assigned lane, which flickers at
    junctions of the roundabout; the nearest lane of the whole network does not.
    """
    lane = road.network.get_lane(road.network.get_closest_lane_index(vehicle.position,
                                                                     vehicle.heading))
    return not lane.on_lane(vehicle.position, margin=margin_m)


def on_network(road, margin_m: float = 0.0):
    """`on_road(centre [2], heading [2], length, width) -> bool` in the world frame for a
    highway-env road: the box's centre on some lane of the network (`centre_off_lane`'s test,
    highway-env's frame has y flipped). What the failure classification's lane changes ask."""
    from types import SimpleNamespace

    def on_road(centre, heading, length, width) -> bool:
        vehicle = SimpleNamespace(position=np.array([float(centre[0]), -float(centre[1])]),
                                  heading=float(np.arctan2(-heading[1], heading[0])))
        return not centre_off_lane(road, vehicle, margin_m)

    return on_road


def lane_width_at(road, vehicle, default_m: float = 4.0) -> float:
    """Width (m) of the lane the highway-env `vehicle` is on (`default_m` when it has none)."""
    try:
        lane = road.network.get_lane(vehicle.lane_index)
        return float(lane.width_at(lane.local_coordinates(vehicle.position)[0]))
    except (AttributeError, KeyError, TypeError, IndexError):
        return default_m


# ---- collision type -------------------------------------------------------------------------

COLLISION_TYPES = ("ego rear-ends", "ego rear-ended", "cut-in", "side-swipe", "head-on", "T-bone")
# classify_collision's labels in the campaign's vocabulary; cut-in has no coarse counterpart and
# keeps its name.
COARSE_COLLISION_NAMES = {"side-swipe": "sideswipe", "T-bone": "side (angle)"}
# Every label a campaign record can hold, in the order of the report's tables.
CAMPAIGN_COLLISION_TYPES = ("ego rear-ends", "ego rear-ended", "sideswipe", "side (angle)", "head-on",
                            "cut-in")


def _wrap(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def in_frame(ego_state: np.ndarray, point: np.ndarray) -> tuple[float, float]:
    """(forward, left) of `point` in the frame of `ego_state` (x, y, heading_x, heading_y, ...)."""
    h = ego_state[2:4] / max(np.linalg.norm(ego_state[2:4]), 1e-12)
    d = point - ego_state[:2]
    return float(d @ h), float(-d[0] * h[1] + d[1] * h[0])


def classify_collision(ego_track: np.ndarray, adv_track: np.ndarray, ego_size: np.ndarray,
                       adv_size: np.ndarray) -> str:
    """Type of the collision at the last step of ego_track / adv_track [K, 6] (the steps leading
    up to it, e.g. the last 3 s; only the last one is needed for all but cut-in).

    With dpsi the adversary's heading relative to the ego's and (forward, lateral) the
    adversary's centre in the ego's frame at the collision:
    - head-on: |dpsi| > 120 deg;
    - T-bone: 60 deg <= |dpsi| <= 120 deg;
    - otherwise (same direction), cut-in: the adversary is ahead (forward > 0) and at some earlier
      step of the tracks it was beside the ego's path, |lateral| >= (w_ego + w_adv) / 2 in the
      ego's frame of that step, i.e. it came into the ego's lane from another;
    - otherwise ego rear-ends / ego rear-ended: the boxes meet through their fronts / rears: the
      longitudinal penetration (l_ego + l_adv) / 2 - |forward| is at most the lateral one
      (w_ego + w_adv) / 2 - |lateral|; "ego rear-ends" when the adversary is ahead;
    - otherwise side-swipe (the boxes meet through their sides).
    """
    ego, adv = ego_track[-1], adv_track[-1]
    dpsi = abs(float(_wrap(np.arctan2(adv[3], adv[2]) - np.arctan2(ego[3], ego[2]))))
    if dpsi > np.radians(120):
        return "head-on"
    if dpsi >= np.radians(60):
        return "T-bone"
    forward, lateral = in_frame(ego, adv[:2])
    half_widths = 0.5 * (float(ego_size[1]) + float(adv_size[1]))
    if forward > 0 and any(abs(in_frame(e, a[:2])[1]) >= half_widths
                           for e, a in zip(ego_track[:-1], adv_track[:-1])):
        return "cut-in"
    long_pen = 0.5 * (float(ego_size[0]) + float(adv_size[0])) - abs(forward)
    lat_pen = half_widths - abs(lateral)
    if long_pen <= lat_pen:
        return "ego rear-ends" if forward > 0 else "ego rear-ended"
    return "side-swipe"


def coarse_collision_name(fine_type: str | None) -> str | None:
    """`classify_collision`'s label in the campaign's vocabulary (None stays None)."""
    return COARSE_COLLISION_NAMES.get(fine_type, fine_type)


def coarse_collision_type(ego, partner) -> str:
    """Campaign monitor's type of a collision between highway-env vehicles (position, heading
    in rad, WIDTH): head-on when |dpsi| >= 150 deg; with |dpsi| <= 30 deg "ego rear-ends" /
    "ego rear-ended" when the boxes overlap laterally (|lateral| < half the sum of the widths;
    partner ahead / behind), else sideswipe; any other angle side (angle)."""
    dpsi = _wrap(partner.heading - ego.heading)
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


# ---- summaries ------------------------------------------------------------------------------

def summarise_metric(values: list[float]) -> dict:
    """{"mean", "p90", "n"} over finite values (None when there are none)."""
    finite = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=np.float64)
    if finite.size == 0:
        return {"mean": None, "p90": None, "n": 0}
    return {"mean": float(finite.mean()), "p90": float(np.percentile(finite, 90)), "n": int(finite.size)}
