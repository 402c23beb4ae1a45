"""Judge an attack: splice generated futures into the record, drive a planner against them, score.

Generated tracks are 2 Hz future states [R, F, 6] (world frame: x, y, heading_x, heading_y,
speed, yaw_rate; F = horizon / 0.5 s, t0 + 0.5 ... t0 + horizon) of window rows `rows` (never the
ego, row 0). `splice_tracks` puts them into a copy of the human's 10 Hz log; `rollout` drives a
planner (SPEC, `riskmap.registry`) in closed loop against the spliced log exactly as
`riskmap evaluate --mode log` does (every other vehicle replays its record, the ego is handed to
the planner at t = 0; `replay` plays the human back; a scene cut from a recording hands it over
at t0 on the recording's lanelets: each kind's source builds its world,
`adversary.crash.scene_source`); `judge` computes STRIVE's metrics.

The rollout ignores highway-env's own contact response for the ego (it would push the ego out of
the other box and end the episode at the first touch): collisions are judged on box overlap
(IoU > 0.02), as STRIVE defines them, over the whole horizon.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from adversary.crash.scene_source import scene_source
from adversary.crash.scenes import CONTROL_HZ, WINDOW_DT_S, SceneRecord
from rasterize.errors import InputError
from rasterize.frames import box_corners
from rasterize.timebase import FUTURE_S, HISTORY_S, REPLAN_HZ
from rasterize.tracks import ReadsTracks, Tracks
from riskmap.registry import cached_planner
from riskmap.sim.records.alternatives import ego_only_solution
from riskmap.sim.records.failures import classify_failure
from riskmap.sim.records.metrics import (
    COLLISION_TYPES,
    STRIVE,
    box_iou,
    box_off_road,
    classify_collision,
    drivable_area,
    min_box_gap,
    off_road_fraction,
)
from riskmap.sim.worlds.log_replay import HumanLog

COLLISION_IOU = STRIVE.collision_iou            # a collision is a box IoU above this
OFF_ROAD_FRACTION = STRIVE.off_road_fraction    # off-road when more than this share of the box is off
# Training windows cut from a drive (`rollout`'s scene_steps): `riskmap collect`'s defaults.
WINDOW_HISTORY_S, WINDOW_FUTURE_S = HISTORY_S, FUTURE_S
ACCEL_WINDOW_S = 2.0            # ego acceleration is measured over this long before the collision
CUT_IN_LOOKBACK_S = 3.0         # a cut-in adversary was beside the ego within this long before
GAP_RADIUS_M = 40.0             # others farther (centre distance) do not count for the min gap
# Accelerations tried with a lane change in the solution check (with the default set along the path).
SOLUTION_LATERAL_ACCELS_MPS2 = (-6.0, -3.0, 0.0, 2.0)
# Box IoU, off-road and the collision classifier are defined in riskmap.sim.records.metrics; callers
# keep importing them from here.
__all__ = ["COLLISION_IOU", "COLLISION_TYPES", "OFF_ROAD_FRACTION", "Rollout", "box_iou", "first_collision", "braking_track",
           "classify_collision", "drivable_area", "ego_future_2hz", "ego_track_2hz", "handover_offsets",
           "judge", "off_road_fraction", "rollout", "splice_tracks"]


def _check_tracks(record: SceneRecord, tracks: np.ndarray, rows) -> tuple[np.ndarray, np.ndarray]:
    tracks = np.asarray(tracks, dtype=np.float64)
    rows = np.asarray(rows, dtype=np.int64).reshape(-1)
    steps = record.scene.future_steps
    if tracks.shape != (len(rows), steps, 6):
        raise InputError(f"tracks must have shape [len(rows)={len(rows)}, {steps}, 6], got {tracks.shape}")
    if not np.isfinite(tracks).all():
        raise InputError("tracks hold non-finite values; check the generator's output")
    n = len(record.agent_ids)
    if (rows <= 0).any() or (rows >= n).any() or len(set(rows.tolist())) != len(rows):
        raise InputError(f"rows {rows.tolist()} must be distinct window rows 1..{n - 1} (row 0 is the "
                         "ego, which the planner drives)")
    return tracks, rows


def splice_tracks(record: SceneRecord, tracks: np.ndarray, rows) -> HumanLog:
    """A copy of the log, truncated at t0 + horizon, in which the agents of window `rows` follow
    `tracks` [len(rows), F, 6] from t0 on, at the log's rate.

    Between the 2 Hz knots (the logged state at t0, then the track) positions follow the cubic
    Hermite curve whose velocity at each knot is that knot's speed times heading (the kinematic
    model's own velocity, so a stop does not overshoot and the splice at t0 has no kink),
    headings the linearly interpolated unwrapped angle, speeds linear; yaw rates are the headings' finite
    differences as the recorder computes them. The spliced agents are valid over the whole
    horizon (one whose record ended stays on the road); every other agent keeps its record.
    """
    tracks, rows = _check_tracks(record, tracks, rows)
    log, k0, stride = record.log, record.t0_step, record.stride
    end = k0 + stride * record.scene.future_steps + 1
    if log.num_steps < end:
        raise InputError(f"the record has {log.num_steps} steps, the horizon needs {end}")
    states, valid = log.states[:, :end].copy(), log.valid[:, :end].copy()
    knots_t = WINDOW_DT_S * np.arange(record.scene.future_steps + 1)
    fine_t = log.dt_s * np.arange(end - k0)
    for row, track in zip(rows, tracks):
        agent = int(record.agent_ids[row])
        start = states[agent, k0]
        knots = np.concatenate([start[None], track])
        unit = knots[:, 2:4] / np.maximum(np.linalg.norm(knots[:, 2:4], axis=1, keepdims=True), 1e-12)
        xy = CubicHermiteSpline(knots_t, knots[:, :2], knots[:, 4:5] * unit)(fine_t)
        angle = np.unwrap(np.arctan2(knots[:, 3], knots[:, 2]))
        heading = np.interp(fine_t, knots_t, angle)
        speed = np.interp(fine_t, knots_t, knots[:, 4])
        yaw_rate = np.concatenate([[start[5]], np.diff(heading) / log.dt_s])
        spliced = np.column_stack([xy, np.cos(heading), np.sin(heading), speed, yaw_rate])
        knot_steps = stride * np.arange(1, record.scene.future_steps + 1)
        spliced[knot_steps] = track           # the knots exactly as generated
        spliced[0] = start
        states[agent, k0:end] = spliced
        valid[agent, k0:end] = True
    return HumanLog(states, valid, log.sizes.copy(), log.kinds.copy(), log.ego_id, log.dt_s,
                    log.crashed, log.off_road)


@dataclass(frozen=True, eq=False)
class Rollout(ReadsTracks):
    """One closed-loop drive of the spliced log.

    tracks: every vehicle's recorded 10 Hz `Tracks` (rows: recorder ids; S = (t0 + horizon) * 10 + 1
    unless the ego left the road earlier; ids: the log agent each recorder agent replays, the ego:
    the log's ego, -1 none); ego: the ego's recorder id. `states`, `valid`, `sizes` and `log_ids`
    read the tracks' (`ReadsTracks`).
    """

    tracks: Tracks
    ego: int
    dt_s: float
    t0_step: int
    planner_spec: str
    drive: dict            # drive_episode's record (off_road, distance_m, plan times, ...)
    wall_s: float
    final_scene: object = None   # the last step with its whole history (`keep_scene`), else None
    scenes: tuple = ()           # `scene_steps`' windows (`rollout`), in their order

    def recorder_id(self, log_id: int) -> int:
        """The recorder agent replaying log agent `log_id` (-1 if it never was on the road)."""
        hits = np.flatnonzero(self.log_ids == log_id)
        return int(hits[0]) if len(hits) else -1

    def row_ids(self, record: SceneRecord) -> np.ndarray:
        """Recorder id [N] of each window row (row 0: the ego)."""
        return np.array([self.recorder_id(int(a)) for a in record.agent_ids], dtype=np.int64)


def with_ego_states(log: HumanLog, ego_states: np.ndarray) -> HumanLog:
    """A copy of `log` whose ego follows `ego_states` [S, 6] (the log's steps, from step 0; valid
    throughout): what log playback (`replay`) then drives."""
    ego_states = np.asarray(ego_states, dtype=np.float64)
    if ego_states.shape != (log.num_steps, 6) or not np.isfinite(ego_states).all():
        raise InputError(f"ego_states must be finite [{log.num_steps}, 6] (the log's steps), got "
                         f"{ego_states.shape}")
    states, valid = log.states.copy(), log.valid.copy()
    states[log.ego_id], valid[log.ego_id] = ego_states, True
    return HumanLog(states, valid, log.sizes.copy(), log.kinds.copy(), log.ego_id, log.dt_s,
                    log.crashed, log.off_road)


def rollout(record: SceneRecord, tracks: np.ndarray, rows, planner, planner_spec: str,
            control_hz: int = CONTROL_HZ, replan_hz: int = REPLAN_HZ, keep_scene: bool = False,
            ego_states: np.ndarray | None = None, scene_steps: tuple[int, ...] = ()) -> Rollout:
    """Drive `planner` (made from `planner_spec`) against the log spliced with `tracks` at `rows`
    (module docstring). Empty `rows` (tracks [0, F, 6]) drives against the untouched record.
    Every scene is driven one way, in the world its kind's source builds
    (`adversary.crash.scene_source`): highway-env's log replay with the ego handed over at t = 0,
    or a CommonRoad recording's lanelets with the ego handed over at t0.
    `keep_scene`: also keep the last step as a `Scene` with the whole drive as history, at the
    control rate, lanes included (the campaign report's frames).

    `ego_states` [S, 6] (the spliced log's steps): the ego follows these states instead of the
    human's record (with `planner` `replay`: a counterfactual ego, `adversary.harden.windows`).
    `scene_steps`: 10 Hz steps at which the drive is cut into training windows (2 s of history
    and 6 s of future at 2 Hz, as `riskmap collect` cuts them; times past the drive invalid),
    returned in `Rollout.scenes`."""
    from riskmap.sim.loop.rollout import drive_world

    started = time.perf_counter()
    if abs(1.0 / control_hz - record.log.dt_s) > 1e-9:
        raise InputError(f"control_hz={control_hz} differs from the record's {1 / record.log.dt_s:g} Hz")
    log = splice_tracks(record, tracks, rows)
    if ego_states is not None:
        log = with_ego_states(log, ego_states)
    world = scene_source(record.scene).world(record, log, planner, planner_spec, control_hz, replan_hz)
    drive = world.record(drive_world(world.run, world.driver, world.loop, world.hooks))
    tracks, ego = world.tracks()
    final_scene = world.final_scene() if keep_scene else None
    windows = tuple(world.window(k) for k in scene_steps)
    return Rollout(tracks, ego, log.dt_s, record.t0_step, planner_spec, drive,
                   time.perf_counter() - started, final_scene, windows)


def ego_track_2hz(result: Rollout, past_steps: int = 4, future_steps: int = 12) -> np.ndarray:
    """The ego's closed-loop states [past_steps + 1 + future_steps, 6] at 2 Hz around t0 (the
    window's time grid; row past_steps is t0). The planner drives from t = 0, so its past differs
    from the human's in the window; past the end of the rollout (the ego left the road) its last
    state is repeated."""
    stride = round(WINDOW_DT_S / result.dt_s)
    steps = result.t0_step + stride * np.arange(-past_steps, future_steps + 1)
    if steps[0] < 0:
        raise InputError(f"past_steps={past_steps} reaches before the start of the rollout")
    last = int(np.flatnonzero(result.valid[result.ego])[-1])
    return result.states[result.ego, np.minimum(steps, last)].copy()


def ego_future_2hz(result: Rollout, future_steps: int = 12) -> np.ndarray:
    """The ego's closed-loop states [future_steps, 6] at t0 + 0.5 ... t0 + 0.5 * future_steps."""
    return ego_track_2hz(result, 0, future_steps)[1:]



def braking_track(record: SceneRecord, row: int, decel_mps2: float = 8.0, into_ego_lane: bool = False,
                  shift_s: float = 1.5) -> np.ndarray:
    """A hand-made adversary [F, 6] for window `row`: from its state at t0 it brakes at
    `decel_mps2` to a stop along its heading; with `into_ego_lane` it also moves sideways onto
    the line through the ego's position at t0, linearly over `shift_s` (headings and speeds follow
    the motion between knots). For tests and examples on straight roads; a learned model
    generates the real ones."""
    state = record.window.states[row, record.window.current_index]
    ego = record.window.states[0, record.window.current_index]
    heading = state[2:4] / np.linalg.norm(state[2:4])
    left = np.array([-heading[1], heading[0]])
    lateral = float((ego[:2] - state[:2]) @ left) if into_ego_lane else 0.0
    times = WINDOW_DT_S * np.arange(1, record.scene.future_steps + 1)
    stop_s = state[4] / decel_mps2
    t = np.minimum(times, stop_s)
    travelled = state[4] * t - 0.5 * decel_mps2 * t ** 2
    shift = lateral * np.minimum(times / shift_s, 1.0)
    xy = state[:2] + travelled[:, None] * heading + shift[:, None] * left
    step = np.diff(np.vstack([state[:2], xy]), axis=0)
    moving = np.linalg.norm(step, axis=1) > 1e-6
    headings = np.tile(heading, (len(times), 1))
    headings[moving] = step[moving] / np.linalg.norm(step[moving], axis=1, keepdims=True)
    speed = np.linalg.norm(step, axis=1) / WINDOW_DT_S
    return np.column_stack([xy, headings, speed, np.zeros(len(times))])


# ---- metrics --------------------------------------------------------------------------------

def first_collision(tracks: Tracks, ego: int, others: list[int], from_step: int = 0
                    ) -> tuple[int | None, int | None, float]:
    """(step, agent, IoU) of the first step >= from_step at which the ego's box overlaps one of
    `others` with IoU > COLLISION_IOU; (None, None, max IoU seen) if never. `tracks` as a
    `Rollout`'s."""
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    reach = 0.5 * (np.hypot(*sizes[ego]) + np.hypot(sizes[:, 0], sizes[:, 1]))
    best = 0.0
    for k in range(from_step, states.shape[1]):
        if not valid[ego, k]:
            continue
        hits = []
        for a in others:
            if valid[a, k] and np.linalg.norm(states[a, k, :2] - states[ego, k, :2]) < reach[a]:
                iou = box_iou(states[ego, k], sizes[ego], states[a, k], sizes[a])
                best = max(best, iou)
                if iou > COLLISION_IOU:
                    hits.append((iou, a))
        if hits:
            iou, a = max(hits)
            return k, a, iou
    return None, None, best


def _first_collision(result: Rollout, ego: int, others: list[int], from_step: int
                     ) -> tuple[int | None, int | None, float]:
    """`first_collision` on a rollout's recorded tracks."""
    return first_collision(result.tracks, ego, others, from_step)


def collided_with(result: Rollout, record: SceneRecord, row: int) -> bool:
    """Whether the ego of `result` hits window `row`'s vehicle from t0 on (the judge's criterion)."""
    agent = int(result.row_ids(record)[row])
    return agent >= 0 and _first_collision(result, result.ego, [agent], result.t0_step)[0] is not None


def _ego_accelerations(result: Rollout, end_step: int) -> tuple[float, float]:
    """(min longitudinal acceleration, max |acceleration vector|), m/s², over the
    ACCEL_WINDOW_S before `end_step`: the first from the speed's finite differences (negative =
    braking), the second from the velocity vector's (it includes the lateral part)."""
    ego = result.ego
    start = max(0, end_step - round(ACCEL_WINDOW_S / result.dt_s))
    seg = result.states[ego, start:end_step + 1][result.valid[ego, start:end_step + 1]]
    if len(seg) < 2:
        return 0.0, 0.0
    velocity = seg[:, 4:5] * seg[:, 2:4]
    along = np.diff(seg[:, 4]) / result.dt_s
    vector = np.linalg.norm(np.diff(velocity, axis=0), axis=1) / result.dt_s
    return float(along.min()), float(vector.max())


def _min_gap(result: Rollout, from_step: int, to_step: int) -> float:
    """Smallest box gap (m) between the ego and any vehicle within GAP_RADIUS_M over the steps."""
    s, v, ego = result.states, result.valid, result.ego
    gaps = []
    for k in range(from_step, to_step + 1):
        if not v[ego, k]:
            continue
        mine = box_corners(s[ego, k, :2], s[ego, k, 2:4], *result.sizes[ego])
        near = [a for a in np.flatnonzero(v[:, k])
                if a != ego and np.linalg.norm(s[a, k, :2] - s[ego, k, :2]) < GAP_RADIUS_M]
        gaps.append(min_box_gap(mine, (box_corners(s[a, k, :2], s[a, k, 2:4], *result.sizes[a])
                                       for a in near)))
    return float(min(gaps, default=float("inf")))


def _worst_off_road(log: HumanLog, spliced: HumanLog, agent: int, steps: list[int], area) -> float:
    """The largest off-road fraction of `agent`'s spliced box over `steps`, counting only steps at
    which the map covers where the agent really was (its logged box is valid and on the lanes):
    a recorded vehicle that drove off the end of a finite map, or through a junction square the
    lane polygons leave uncovered, is not off the road there."""
    fracs = [off_road_fraction(spliced.states[agent, k], spliced.sizes[agent], area) for k in steps
             if spliced.valid[agent, k] and k < log.num_steps and log.valid[agent, k]
             and off_road_fraction(log.states[agent, k], log.sizes[agent], area) <= OFF_ROAD_FRACTION]
    return max(fracs, default=0.0)


def judge(record: SceneRecord, tracks: np.ndarray, rows, adversary_row: int, planner,
          planner_spec: str, result: Rollout | None = None) -> dict:
    """STRIVE's metrics of one attack (JSON-ready); `result`: a rollout of these tracks already
    driven (else one is driven here). Times are seconds of the episode (t0 = scene.t0_s).

    collision / collision_time_s / collision_iou: the ego's box overlaps the adversary's with IoU
      > 0.02 at some 10 Hz step from t0 on (the first such step; collision_iou is the IoU there,
      or the largest IoU seen without a collision); collision_any (_time_s, _row):
      the same with any vehicle (row -1: a vehicle outside the window); collision_before_t0: the
      planner already hit something before the attack started (the attack is then moot).
    adversary_off_road / other_off_road: more than 5% of the box outside the union of the
      window's lane polygons at some 2 Hz step t0 + 0.5 ... up to the collision (the whole
      horizon without one) at which the map covers the vehicle's logged box (`_worst_off_road`);
      "other": every window row but the ego and the adversary, at its spliced (generated or
      logged) state. adversary_off_road_max / other_off_road_max: the
      largest fractions seen.
    kinematic_value_mps: |v_ego - v_adv| (velocity vectors) at the collision (None without one).
    ego_min_accel_mps2 / ego_max_abs_accel_mps2: see `_ego_accelerations`, over the 2 s before
      the collision (before the end of the rollout without one).
    collision_type: `classify_collision` over the 3 s before the collision (None without one).
    solution_found: STRIVE's solution check (`riskmap.sim.records.alternatives.ego_only_solution` on the
      rollout: could the ego alone, from 3 s before, have avoided every box): along its own path
      with constant accelerations (solution_found_longitudinal), or moving one lane width left or
      right within 2 s while staying on the road; None without a collision.
    failure: the collision with the adversary classified (`riskmap.sim.records.failures.classify_failure`:
      fault, avoidable by a driver who reacts once the threat is visible, a valid attack); without
      one, the ego's first collision with any other vehicle from t0 (no attack to validate);
      None without a collision.
    off_road: the ego, by the episode's own check (the ego off every lane, once a second) at any time of
      the rollout, after a collision too.
    distance_m: distance the ego drove from t0 to the collision (to the end without one);
    min_gap_m: smallest box gap between the ego and any vehicle within 40 m over the same span.
    """
    tracks, rows = _check_tracks(record, tracks, rows)
    if not 0 < adversary_row < len(record.agent_ids):
        raise InputError(f"adversary_row={adversary_row} must be a window row 1..{len(record.agent_ids) - 1}")
    if result is None:
        result = rollout(record, tracks, rows, planner, planner_spec)
    ego, dt, k0 = result.ego, result.dt_s, result.t0_step
    row_ids = result.row_ids(record)
    adv = int(row_ids[adversary_row])
    if adv < 0:
        raise InputError(f"adversary_row={adversary_row} never appeared in the rollout")
    everyone = [a for a in range(len(result.sizes)) if a != ego]
    k_coll, _, iou = _first_collision(result, ego, [adv], k0)
    k_any, with_any, _ = _first_collision(result, ego, everyone, k0)
    k_before, _, _ = _first_collision(result, ego, everyone, 0) if k0 > 0 else (None, None, 0)
    last = int(np.flatnonzero(result.valid[ego])[-1])
    end = k_coll if k_coll is not None else last

    # Off-road at the 2 Hz steps of the generated horizon up to the collision.
    spliced = splice_tracks(record, tracks, rows)
    area = drivable_area(record.window.lanes)
    stride = record.stride
    knot_steps = [k for k in k0 + stride * np.arange(1, record.scene.future_steps + 1) if k <= end]
    adv_frac, other_frac = 0.0, 0.0
    for row, agent in enumerate(record.agent_ids):
        if row == 0:
            continue
        worst = _worst_off_road(record.log, spliced, int(agent), knot_steps, area)
        if row == adversary_row:
            adv_frac = worst
        else:
            other_frac = max(other_frac, worst)

    metrics = {
        "planner": planner_spec, "adversary_row": int(adversary_row), "spliced_rows": rows.tolist(),
        "collision": k_coll is not None,
        "collision_time_s": None if k_coll is None else round(k_coll * dt, 6),
        "collision_iou": float(iou),
        "collision_any": k_any is not None,
        "collision_any_time_s": None if k_any is None else round(k_any * dt, 6),
        "collision_any_row": None if k_any is None else
        (int(np.flatnonzero(row_ids == with_any)[0]) if with_any in row_ids else -1),
        "collision_before_t0": k_before is not None and k_before < k0,
        "adversary_off_road": adv_frac > OFF_ROAD_FRACTION, "adversary_off_road_max": adv_frac,
        "other_off_road": other_frac > OFF_ROAD_FRACTION, "other_off_road_max": other_frac,
        "kinematic_value_mps": None, "collision_type": None, "solution_found": None,
        "solution_found_longitudinal": None, "failure": None,
        "off_road": bool(result.drive["off_road"]),
    }
    metrics["ego_min_accel_mps2"], metrics["ego_max_abs_accel_mps2"] = _ego_accelerations(result, end)
    lane_m = float(np.median([lane.width_m for lane in record.window.lanes])) if record.window.lanes else 4.0
    if k_coll is not None:
        s = result.states
        v_ego = s[ego, k_coll, 4] * s[ego, k_coll, 2:4]
        v_adv = s[adv, k_coll, 4] * s[adv, k_coll, 2:4]
        metrics["kinematic_value_mps"] = float(np.linalg.norm(v_ego - v_adv))
        lo = max(0, k_coll - round(CUT_IN_LOOKBACK_S / dt))
        both = result.valid[ego, lo:k_coll + 1] & result.valid[adv, lo:k_coll + 1]
        metrics["collision_type"] = classify_collision(s[ego, lo:k_coll + 1][both], s[adv, lo:k_coll + 1][both],
                                                       result.sizes[ego], result.sizes[adv])
        longitudinal = ego_only_solution(result.tracks, ego, k_coll, dt)

        def on_road(centre, heading, length, width):
            state = np.array([*centre, *heading])
            return not box_off_road(state, (length, width), area)

        metrics["solution_found_longitudinal"] = bool(longitudinal)
        metrics["solution_found"] = bool(longitudinal) or bool(ego_only_solution(
            result.tracks, ego, k_coll, dt, accels_mps2=SOLUTION_LATERAL_ACCELS_MPS2,
            lateral_offsets_m=(lane_m, -lane_m), on_road=on_road))
        metrics["failure"] = classify_failure(result.tracks, ego, adv, k_coll, dt, attack=True,
                                              on_road=on_road, lane_width_m=lane_m,
                                              adversary_off_road=adv_frac > OFF_ROAD_FRACTION, from_step=k0,
                                              limits=scene_source(record.scene).limits)
    elif k_any is not None and with_any is not None:       # the ego hit someone else: a failure too
        metrics["failure"] = classify_failure(result.tracks, ego, int(with_any), k_any,
                                              dt, lane_width_m=lane_m, from_step=k0)
    path = result.states[ego, k0:end + 1, :2][result.valid[ego, k0:end + 1]]
    metrics["distance_m"] = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    gap = _min_gap(result, k0, end)
    metrics["min_gap_m"] = gap if np.isfinite(gap) else None       # None: nobody within 40 m
    metrics["rollout_s"] = result.wall_s
    return metrics


def handover_offsets(env_id: str, seed: int, episodes: int, specs: tuple[str, ...]) -> dict:
    """Per SPEC: seconds per rollout (untouched record) and the distance (m) between the ego's
    closed-loop position at t0 and the human's logged one (the planner drives from t = 0, so by
    t0 it is no longer where the window's history says), over scenes 0..episodes-1."""
    from adversary.crash.scenes import AttackScene, record_attack_scene

    records = []
    for episode in range(episodes):
        try:
            records.append(record_attack_scene(AttackScene(env_id, seed, episode)))
        except InputError:
            continue
    out = {"env_id": env_id, "seed": seed, "scenes": len(records)}
    for spec in specs:
        planner = cached_planner(spec)
        seconds, offsets = [], []
        for record in records:
            empty = np.zeros((0, record.scene.future_steps, 6))
            result = rollout(record, empty, [], planner, spec)
            seconds.append(result.wall_s)
            here = result.states[result.ego, record.t0_step, :2]
            offsets.append(float(np.linalg.norm(here - record.log.states[record.log.ego_id, record.t0_step, :2])))
        out[spec] = {"seconds_per_rollout_mean": float(np.mean(seconds)),
                     "t0_offset_m_mean": float(np.mean(offsets)), "t0_offset_m_max": float(np.max(offsets))}
    return out
