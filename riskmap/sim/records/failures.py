"""Failures that count: the fault, avoidability and validity of one collision, each defined once.

A collision says something about the planner under test only if the ego could have avoided it;
an attack says something only if the adversary did it alone and drove like a car. Every
collision record of every attack, the search, the aggressive neighbour and natural traffic,
simulated or recorded, is classified by `classify_failure` on the recorder's `Tracks`
(rasterize.tracks: states, valid, sizes over A agents and S steps), `ego` and `other` agent
indices, `collision_step` an index into S, dt_s the step (s).

fault (`collision_fault`): where the other is, seen from the ego at the collision step: the
angle between the ego's heading and the line from its centre to the other's (nuPlan's rule for
at-fault collisions, its 30 and 150 degree tolerances):
- "at fault": the other is ahead, within `AHEAD_DEG` of the ego's heading (the ego drove into
  it: a rear-end, a head-on, a cut-in it did not brake for);
- "struck from behind": the other is behind, beyond `BEHIND_DEG`;
- "side": anything between (a sideswipe or a T-bone; whose fault it was is left open: nuPlan
  blames the ego only when it was changing lanes).
This is the rule `evaluate --commonroad` used (the other ahead of the ego: at fault), with the
contacts beside the ego told apart.

avoidable (`avoidability`): a driver who reacts to what can be seen could have avoided it.
- The threat became visible at the first step of the last uninterrupted run of steps, ending at
  the collision, in which the other's constant-velocity prediction meets the ego's within
  `VISIBILITY_HORIZON_S` (3 s, checked every 0.1 s; an overlap now counts). A threat that
  no constant-velocity prediction saw coming is visible only at the collision.
- The ego reacts `REACTION_S` (0.5 s) later. From its recorded state then, it tries each
  alternative (`riskmap.sim.records.alternatives.alternative_track`): the constant accelerations
  `AVOID_ACCELS_MPS2` along its own recorded path (braking profiles, holding speed, speeding up)
  and, where the caller can say what is on the road (`on_road`), a lane change of one lane
  width left or right, blended in over 2 s, with `AVOID_LANE_CHANGE_ACCELS_MPS2`.
- An alternative avoids the collision if its box overlaps no agent's recorded box from the
  reaction to `AFTER_COLLISION_S` past the collision step (or the end of the record) and, when
  it leaves the path sideways, stays on the road. Everybody else does what the record says: a
  follower that rear-ends an ego braking hard makes that alternative fail.
- No time to react (the reaction falls at or after the collision) is unavoidable.
STRIVE's hindsight solution check (`alternatives.ego_only_solution`, 3 s before the collision
whatever the ego could see) stays beside it under its own name.

valid attack (`attack_validity`, attacks only): the adversary, from `from_step` (the attack's
start) until the collision,
- hits no agent but the ego (box IoU above STRIVE's 0.02 with any other agent);
- stays on the drivable area (the caller's judgement, `off_road`: None when it cannot tell);
- stays within the kinematic limits below, measured as averages over `KINEMATIC_WINDOW_S`
  (0.5 s; one 10 Hz step's rounding must not decide validity): longitudinal acceleration in
  [-MAX_BRAKE_MPS2, MAX_ACCEL_MPS2], |lateral acceleration| = speed * |yaw rate| at most
  MAX_LATERAL_ACCEL_MPS2, |yaw rate| at most MAX_YAW_RATE_RADPS, and sideways motion across the
  direction of travel (the chord over `TRAVEL_CHORD_S`) at most MAX_LANES_PER_S lane widths in
  any 1 s. In a highway-env world the lateral limit is the simulator's own drivers'
  (`HIGHWAY_ENV_LIMITS`): its lane changes exceed a car's grip.

A record without the trajectories these need (an older run) is classified "unknown", counted
as such and never guessed (`UNKNOWN`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.frames import box_corners
from rasterize.geometry import box_gap, boxes_overlap
from rasterize.tracks import Tracks
from riskmap.sim.records.alternatives import first_clear_alternative
from riskmap.sim.records.metrics import STRIVE, box_iou, in_frame, overlap_within

FAULTS = ("at fault", "struck from behind", "side")
UNKNOWN = "unknown"            # the class of a record without trajectories

AHEAD_DEG, BEHIND_DEG = 30.0, 150.0   # nuPlan's tolerances for an agent ahead of / behind the ego
VISIBILITY_HORIZON_S = 3.0     # constant-velocity look-ahead that makes a threat visible (issue's rule)
VISIBILITY_STEP_S = 0.1        # time resolution of that look-ahead
REACTION_S = 0.5               # a driver's reaction time after the threat is visible
AFTER_COLLISION_S = 2.0        # an alternative must stay clear this long past the collision step
# Ego-only alternatives (m/s²): full braking (≈ 0.8 g) to speeding up, along the ego's own path.
AVOID_ACCELS_MPS2 = (-8.0, -6.0, -4.0, -2.0, 0.0, 1.0, 2.0, 3.0)
AVOID_LANE_CHANGE_ACCELS_MPS2 = (-6.0, -3.0, 0.0, 2.0)   # combined with a lane change
LANE_CHANGE_BLEND_S = 2.0      # a lane change's duration (smoothstep)

# Kinematic limits of a valid adversary, with their source.
# Full braking of a passenger car on dry asphalt: tyre-road friction μ ≈ 0.9, 0.9 g ≈ 8.8 m/s²;
# 9.0 leaves the rounding of a 10 Hz track.
MAX_BRAKE_MPS2 = 9.0
# A quick passenger car, 0-100 km/h in about 7 s: 27.8 m/s / 7 s ≈ 4.0 m/s².
MAX_ACCEL_MPS2 = 4.0
# Cornering at the grip limit of a passenger car's tyres, about 0.7 g (≈ 6.9 m/s²; sports cars on a
# skidpad reach 0.9 g): 7.0.
MAX_LATERAL_ACCEL_MPS2 = 7.0
# A passenger car's minimum turning circle (radius ≈ 5.5 m) at walking pace (5.5 m/s) turns at
# 1 rad/s; faster than that the lateral limit above binds first.
MAX_YAW_RATE_RADPS = 1.0
# Lane changes in recorded highway traffic last from about 1 s to over 10 s (NGSIM's US-101 and
# I-80 lane changes: Toledo & Zohar 2007); crossing more than one lane width within 1 s is not
# a lane change a driver makes.
MAX_LANES_PER_S = 1.0
LANE_WIDTH_M = 3.7             # a US lane, where the caller knows no lane width (lanes per second)
KINEMATIC_WINDOW_S = 0.5       # accelerations and yaw rates are averages over this long
TRAVEL_CHORD_S = 4.0           # the direction of travel is the chord over this long (straight roads)


@dataclass(frozen=True)
class KinematicLimits:
    """The limits a valid adversary keeps (m/s², rad/s, lane widths per second)."""

    max_brake_mps2: float = MAX_BRAKE_MPS2
    max_accel_mps2: float = MAX_ACCEL_MPS2
    max_lateral_accel_mps2: float = MAX_LATERAL_ACCEL_MPS2
    max_yaw_rate_radps: float = MAX_YAW_RATE_RADPS
    max_lanes_per_s: float = MAX_LANES_PER_S


CAR_LIMITS = KinematicLimits()           # a real car's: recorded traffic
# highway-env's own IDM/MOBIL vehicles change lanes with up to 12.7 m/s² of lateral acceleration
# (speed * yaw rate, 0.5 s means; p99 12.5) while keeping every other limit (yaw rate at most
# 0.72 rad/s, 0.83 lanes/s, braking 1.6 m/s²): measured over every vehicle of 6 highway-v0
# episodes (`experiments/failure_classes.py --simulator-limits`). An attack in a highway-env
# world is held to what that world's own drivers do where it exceeds a car: its lane changes
# are the simulator's.
HIGHWAY_ENV_LIMITS = KinematicLimits(max_lateral_accel_mps2=13.0)


@dataclass(frozen=True)
class Avoidance:
    """The reaction that avoids a collision: when it starts and what the ego does."""

    visible_step: int          # the threat became visible at this step
    reaction_step: int         # the ego's alternative starts here (visible + REACTION_S)
    accel_mps2: float | None   # None: nothing avoided it (or there was no time)
    offset_m: float | None     # sideways shift of the path (left positive), 0 along it

    @property
    def avoidable(self) -> bool:
        return self.accel_mps2 is not None


def collision_fault(ego_state: np.ndarray, other_state: np.ndarray) -> str:
    """"at fault", "struck from behind" or "side": where the other's centre lies from the ego's
    heading (module docstring). States [>= 4] world (x, y, heading_x, heading_y, ...)."""
    forward, left = in_frame(ego_state, other_state[:2])
    bearing = np.degrees(np.arctan2(abs(left), forward))       # 0 straight ahead, 180 behind
    if bearing < AHEAD_DEG:
        return "at fault"
    if bearing > BEHIND_DEG:
        return "struck from behind"
    return "side"


def _cv_meets(states, sizes, ego: int, other: int, step: int) -> bool:
    """Whether the ego's and the other's boxes overlap now or within VISIBILITY_HORIZON_S when
    both keep their velocity (speed along heading)."""
    e, o = states[ego, step], states[other, step]
    mine = box_corners(e[:2], e[2:4], *sizes[ego])
    theirs = box_corners(o[:2], o[2:4], *sizes[other])
    if boxes_overlap(mine, theirs):
        return True
    return overlap_within(mine, e[4] * e[2:4], theirs, o[4] * o[2:4], VISIBILITY_HORIZON_S, VISIBILITY_STEP_S)


def threat_visible_step(tracks: Tracks, ego: int, other: int, collision_step: int, from_step: int = 0) -> int:
    """The first step of the last uninterrupted run (ending at `collision_step`, not before
    `from_step`) in which the constant-velocity predictions of `ego` and `other` meet; the
    collision step itself when none did just before it."""
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    step = collision_step
    while step - 1 >= from_step and valid[ego, step - 1] and valid[other, step - 1] \
            and _cv_meets(states, sizes, ego, other, step - 1):
        step -= 1
    return step


def avoidability(tracks: Tracks, ego: int, other: int, collision_step: int, dt_s: float, on_road=None,
                 lane_width_m: float | None = None, from_step: int = 0) -> Avoidance:
    """Whether (and how) the ego could have avoided the collision after seeing it coming (module
    docstring). `on_road(centre [2], heading [2], length, width) -> bool` and `lane_width_m`
    enable the lane-change alternatives; without them only the longitudinal ones are tried."""
    states, valid = tracks.states, tracks.valid
    visible = threat_visible_step(tracks, ego, other, collision_step, from_step)
    react = visible + round(REACTION_S / dt_s)
    if react >= collision_step:
        return Avoidance(visible, react, None, None)
    until = min(states.shape[1] - 1, collision_step + round(AFTER_COLLISION_S / dt_s))
    while until > collision_step and not valid[ego, until] and not valid[other, until]:
        until -= 1               # the record ended: judge up to its last step
    found = first_clear_alternative(tracks, ego, react, until, dt_s, AVOID_ACCELS_MPS2)
    if found is None and on_road is not None and lane_width_m:
        found = first_clear_alternative(tracks, ego, react, until, dt_s,
                                        AVOID_LANE_CHANGE_ACCELS_MPS2, (lane_width_m, -lane_width_m),
                                        blend_s=LANE_CHANGE_BLEND_S, on_road=on_road)
    if found is None:
        return Avoidance(visible, react, None, None)
    return Avoidance(visible, react, float(found[0]), float(found[1]))


def _window_mean(values: np.ndarray, width: int) -> np.ndarray:
    """Means over every `width` consecutive values (all of them when there are fewer)."""
    width = max(1, min(width, len(values)))
    c = np.concatenate([[0.0], np.cumsum(values)])
    return (c[width:] - c[:-width]) / width


def adversary_kinematics(track: np.ndarray, dt_s: float, lane_width_m: float) -> dict:
    """Extremes of an adversary's motion, track [K, 6] (its valid steps in order): the most
    negative / positive longitudinal acceleration (m/s²), the largest |lateral acceleration|
    (m/s²), |yaw rate| (rad/s) and lanes crossed in any 1 s (lane widths); window means over
    KINEMATIC_WINDOW_S (module docstring)."""
    out = {"min_accel_mps2": 0.0, "max_accel_mps2": 0.0, "max_lateral_accel_mps2": 0.0,
           "max_yaw_rate_radps": 0.0, "max_lanes_per_s": 0.0}
    if len(track) < 2:
        return out
    w = max(1, round(KINEMATIC_WINDOW_S / dt_s))
    accel = _window_mean(np.diff(track[:, 4]) / dt_s, w)
    heading = np.unwrap(np.arctan2(track[:, 3], track[:, 2]))
    yaw = _window_mean(np.diff(heading) / dt_s, w)
    speed = _window_mean(0.5 * (track[1:, 4] + track[:-1, 4]), w)
    out["min_accel_mps2"], out["max_accel_mps2"] = float(min(accel.min(), 0.0)), float(max(accel.max(), 0.0))
    out["max_lateral_accel_mps2"] = float(np.abs(speed * yaw).max())
    out["max_yaw_rate_radps"] = float(np.abs(yaw).max())
    second, chord = max(1, round(1.0 / dt_s)), max(1, round(TRAVEL_CHORD_S / dt_s))
    lanes = 0.0
    for k in range(len(track) - second):
        lo, hi = max(0, k + second // 2 - chord // 2), min(len(track) - 1, k + second // 2 + chord // 2)
        direction = track[hi, :2] - track[lo, :2]
        norm = float(np.linalg.norm(direction))
        if norm < 1.0:            # standing (nearly) still: no direction of travel to cross
            continue
        left = np.array([-direction[1], direction[0]]) / norm
        lanes = max(lanes, abs(float((track[k + second, :2] - track[k, :2]) @ left)) / lane_width_m)
    out["max_lanes_per_s"] = lanes
    return out


def kinematic_violations(kinematics: dict, limits: KinematicLimits = CAR_LIMITS) -> list[str]:
    """The limits `adversary_kinematics`' extremes break (the names of the module's constants)."""
    broken = []
    if kinematics["min_accel_mps2"] < -limits.max_brake_mps2:
        broken.append("MAX_BRAKE_MPS2")
    if kinematics["max_accel_mps2"] > limits.max_accel_mps2:
        broken.append("MAX_ACCEL_MPS2")
    if kinematics["max_lateral_accel_mps2"] > limits.max_lateral_accel_mps2:
        broken.append("MAX_LATERAL_ACCEL_MPS2")
    if kinematics["max_yaw_rate_radps"] > limits.max_yaw_rate_radps:
        broken.append("MAX_YAW_RATE_RADPS")
    if kinematics["max_lanes_per_s"] > limits.max_lanes_per_s:
        broken.append("MAX_LANES_PER_S")
    return broken


def revalidated(failure: dict, limits: KinematicLimits) -> dict:
    """A stored attack classification judged again under other `limits`, from the extremes it
    keeps (`kinematics`): whether it is valid and counts, without driving it again."""
    if failure is None or failure.get("kinematics") is None:
        return failure
    reasons = [r for r in failure["invalid_reasons"] if not r.startswith("MAX_")]     # hits, off road
    reasons += kinematic_violations(failure["kinematics"], limits)
    valid = not reasons
    return {**failure, "valid_attack": valid, "invalid_reasons": reasons,
            "counts": bool(valid and failure["avoidable"] and failure["fault"] == "at fault")}


def other_hits(tracks: Tracks, agent: int, exclude: int, from_step: int, to_step: int) -> list[int]:
    """Agents (but `exclude`) whose box `agent`'s overlaps with IoU above STRIVE's 0.02 at some
    step from_step ... to_step - 1."""
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    reach = 0.5 * (np.hypot(*sizes[agent]) + np.hypot(sizes[:, 0], sizes[:, 1]))
    hit = set()
    for k in range(from_step, to_step):
        if not valid[agent, k]:
            continue
        near = np.flatnonzero(valid[:, k] & (np.linalg.norm(states[:, k, :2] - states[agent, k, :2], axis=1) < reach))
        for a in near:
            if a in (agent, exclude) or a in hit:
                continue
            if box_iou(states[agent, k], sizes[agent], states[a, k], sizes[a]) > STRIVE.collision_iou:
                hit.add(int(a))
    return sorted(hit)


def attack_validity(tracks: Tracks, ego: int, adversary: int, collision_step: int, dt_s: float,
                    lane_width_m: float, off_road: bool | None = None, from_step: int = 0,
                    limits: KinematicLimits = CAR_LIMITS) -> dict:
    """{"valid", "reasons", "kinematics", "hit_agents"}: whether the adversary caused the
    collision alone, on the road and within the kinematic limits (module docstring); reasons
    name what failed ("hit another agent", "off road", a limit's constant)."""
    hits = other_hits(tracks, adversary, ego, from_step, collision_step)
    span = np.arange(from_step, collision_step + 1)
    track = tracks.states[adversary, span][tracks.valid[adversary, span]]
    kinematics = adversary_kinematics(track, dt_s, lane_width_m)
    reasons = (["hit another agent"] if hits else []) + (["off road"] if off_road else []) \
        + kinematic_violations(kinematics, limits)
    return {"valid": not reasons, "reasons": reasons, "kinematics": kinematics, "hit_agents": hits}


def road_rules(lanes) -> dict:
    """`classify_failure`'s `on_road` and `lane_width_m` from a recording's lanes (its drivable
    area and median lane width), so lane changes that keep the box on them count as on the road;
    no lanes: neither (the classifier's defaults)."""
    from riskmap.sim.records.metrics import box_off_road, drivable_area

    if not lanes:
        return {}
    area = drivable_area(lanes)

    def on_road(centre, heading, length, width):
        return not box_off_road(np.array([*centre, *heading]), (length, width), area)

    return {"on_road": on_road, "lane_width_m": float(np.median([lane.width_m for lane in lanes]))}


def classify_failure(tracks: Tracks, ego: int, other: int, collision_step: int, dt_s: float, *,
                     attack: bool = False, on_road=None, lane_width_m: float | None = None,
                     adversary_off_road: bool | None = None, from_step: int = 0,
                     limits: KinematicLimits = CAR_LIMITS) -> dict:
    """The classification of one collision between `ego` and `other` (JSON-ready):

    fault, avoidable, visible_time_s / reaction_time_s (times of the record, steps * dt_s),
    avoidance ({"accel_mps2", "offset_m"} of the alternative that avoids it, else None);
    with `attack` (`other` is the adversary) valid_attack and invalid_reasons, kinematics and
    hit_agents; counts: what the headline counts, a valid (attacks), avoidable, at-fault failure.
    `limits`: the kinematic limits of a valid attack (HIGHWAY_ENV_LIMITS in highway-env worlds).
    """
    fault = collision_fault(tracks.states[ego, collision_step], tracks.states[other, collision_step])
    avoid = avoidability(tracks, ego, other, collision_step, dt_s, on_road, lane_width_m, from_step)
    out = {
        "fault": fault, "avoidable": avoid.avoidable,
        "visible_time_s": round(avoid.visible_step * dt_s, 6),
        "reaction_time_s": round(avoid.reaction_step * dt_s, 6),
        "avoidance": {"accel_mps2": avoid.accel_mps2, "offset_m": avoid.offset_m} if avoid.avoidable else None,
    }
    valid_attack = True
    if attack:
        validity = attack_validity(tracks, ego, other, collision_step, dt_s, lane_width_m or LANE_WIDTH_M,
                                   adversary_off_road, from_step, limits)
        valid_attack = validity["valid"]
        out.update(valid_attack=valid_attack, invalid_reasons=validity["reasons"],
                   kinematics=validity["kinematics"], hit_agents=validity["hit_agents"])
    out["counts"] = bool(valid_attack and avoid.avoidable and fault == "at fault")
    return out


def unknown_failure(attack: bool = False) -> dict:
    """The classification of a collision whose record has no trajectories: unknown, never guessed."""
    out = {"fault": UNKNOWN, "avoidable": None, "visible_time_s": None, "reaction_time_s": None,
           "avoidance": None, "counts": None}
    if attack:
        out.update(valid_attack=None, invalid_reasons=[], kinematics=None, hit_agents=[])
    return out


def summarise_failures(classified: list[dict | None], trials: int) -> dict:
    """Counts of each class over the collisions' classifications (None or "unknown" fault: a
    record without trajectories) out of `trials` episodes or scenes: collisions; unknown; at_fault,
    struck_from_behind, side; avoidable; valid (attacks; None when no record says); counted (a
    valid, avoidable, at-fault failure) with its rate over `trials` and 95% Wilson interval."""
    from riskmap.infra.stats import wilson

    known = [c for c in classified if c and c.get("fault") not in (None, UNKNOWN)]
    attacks = [c for c in known if c.get("valid_attack") is not None]
    counted = sum(bool(c["counts"]) for c in known)
    ci = wilson(counted, trials)
    return {
        "collisions": len(classified), "unknown": len(classified) - len(known),
        "at_fault": sum(c["fault"] == "at fault" for c in known),
        "struck_from_behind": sum(c["fault"] == "struck from behind" for c in known),
        "side": sum(c["fault"] == "side" for c in known),
        "avoidable": sum(bool(c["avoidable"]) for c in known),
        "valid": sum(bool(c["valid_attack"]) for c in attacks) if attacks else None,
        "counted": counted, "trials": trials,
        "counted_rate": counted / trials if trials else None,
        "counted_ci95": None if ci is None else [round(ci["lo"], 4), round(ci["hi"], 4)],
    }


# highway-env flags a crash when two boxes will intersect within the step (its check moves them
# by their velocities), so a crashed record's boxes may stop short of touching: the nearest box
# within this gap at the ego's last step is taken as the partner then.
CRASH_FLAG_GAP_M = 3.0


def first_contact(tracks: Tracks, ego: int, from_step: int = 0, crash_flagged: bool = False
                  ) -> tuple[int, int] | None:
    """(step, agent) of the ego's first box overlap with another agent from `from_step` on (the
    nearest such agent when several); None if it never touches one. For drives whose record
    keeps no partner (a highway-env episode's crash flag names none): with `crash_flagged` and no
    overlap, the ego's last step and the agent nearest to it there within CRASH_FLAG_GAP_M."""
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    reach = 0.5 * (np.hypot(*sizes[ego]) + np.hypot(sizes[:, 0], sizes[:, 1]))
    for k in range(from_step, states.shape[1]):
        if not valid[ego, k]:
            continue
        distance = np.linalg.norm(states[:, k, :2] - states[ego, k, :2], axis=1)
        near = np.flatnonzero(valid[:, k] & (distance < reach))
        mine = box_corners(states[ego, k, :2], states[ego, k, 2:4], *sizes[ego])
        hits = [a for a in near[np.argsort(distance[near])] if a != ego
                and boxes_overlap(mine, box_corners(states[a, k, :2], states[a, k, 2:4], *sizes[a]))]
        if hits:
            return k, int(hits[0])
    if crash_flagged:
        last = int(np.flatnonzero(valid[ego])[-1])
        mine = box_corners(states[ego, last, :2], states[ego, last, 2:4], *sizes[ego])
        gaps = [(box_gap(mine, box_corners(states[a, last, :2], states[a, last, 2:4], *sizes[a])), int(a))
                for a in np.flatnonzero(valid[:, last]) if a != ego
                and np.linalg.norm(states[a, last, :2] - states[ego, last, :2]) < 20.0]
        if gaps and min(gaps)[0] <= CRASH_FLAG_GAP_M:
            return last, min(gaps)[1]
    return None


def failure_words(failure: dict) -> str:
    """A classification in a few words: "counts: at fault, avoidable, valid attack" or "does not
    count: struck from behind, unavoidable" (what a panel's title or a table cell says)."""
    if failure.get("fault") in (None, UNKNOWN):
        return "unclassified (a record without trajectories)"
    words = [failure["fault"], "avoidable" if failure["avoidable"] else "unavoidable"]
    if "valid_attack" in failure:
        words.append("valid attack" if failure["valid_attack"] else
                     "invalid attack (" + ", ".join(failure["invalid_reasons"]) + ")")
    return ("counts: " if failure["counts"] else "does not count: ") + ", ".join(words)


def failure_explanation(failure: dict | None) -> str | None:
    """The sentences a job page says about its collision's class and why (None: no collision)."""
    if failure is None:
        return None
    if failure.get("fault") in (None, UNKNOWN):
        return "This collision is not classified: its record was written without the trajectories it needs."
    head = ("It counts as a failure of the planner" if failure["counts"]
            else "It does not count as a failure of the planner")
    fault = {"at fault": "the other vehicle was ahead of the ego (at fault)",
             "struck from behind": "the other vehicle came from behind (struck from behind)",
             "side": "the other vehicle was beside the ego (a side contact)"}[failure["fault"]]
    seen = f"the threat was visible at t = {failure['visible_time_s']:.1f} s"
    avoid = failure.get("avoidance")
    if avoid:
        how = (f"braking at {-avoid['accel_mps2']:.0f} m/s²" if avoid["accel_mps2"] < 0 else
               "holding its speed" if avoid["accel_mps2"] == 0 else f"speeding up at {avoid['accel_mps2']:.0f} m/s²")
        if avoid["offset_m"]:
            how += f" while changing lanes {'left' if avoid['offset_m'] > 0 else 'right'}"
        avoidable = (f"{seen}, and {how} from t = {failure['reaction_time_s']:.1f} s (0.5 s later) "
                     "would have hit nobody (avoidable)")
    else:
        avoidable = (f"{seen}, and no braking, holding, speeding up or lane change from "
                     f"t = {failure['reaction_time_s']:.1f} s missed every vehicle (unavoidable)")
    text = f"{head}: {fault}; {avoidable}"
    if "valid_attack" in failure:
        text += ("; the adversary did it alone, on the road and within a car's limits (a valid attack)"
                 if failure["valid_attack"] else
                 "; the attack is not valid: " + ", ".join(failure["invalid_reasons"]))
    return text + "."


def classify_run(run, adversary=None, contact: tuple[int, int] | None = None,
                 adversary_off_road: bool | None = None) -> dict | None:
    """`classify_failure` of a highway-env episode's collision (`riskmap.sim.worlds.episode.Episode`:
    its recorder, road and ego): `contact` (step, recorder agent), else the first box contact
    (`first_contact`, crash-flagged); an attack when the partner is `adversary` (a highway-env
    vehicle), held to HIGHWAY_ENV_LIMITS; lane changes on the road network. None when no contact
    is found."""
    from riskmap.sim.records.metrics import lane_width_at, on_network

    tracks = run.recorder.tracks()
    ego = run.recorder.ego_id
    contact = contact or first_contact(tracks, ego, crash_flagged=True)
    if contact is None:
        return None
    step, partner = contact
    road = run.base.road
    attack = adversary is not None and partner == run.recorder.known_id(adversary)
    return classify_failure(tracks, ego, partner, step, run.dt, attack=attack,
                            on_road=on_network(road), lane_width_m=lane_width_at(road, run.ego),
                            adversary_off_road=adversary_off_road, limits=HIGHWAY_ENV_LIMITS)
