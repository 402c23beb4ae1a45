"""The failure classification on hand-built scenes of a straight two-lane road (10 Hz)."""

import numpy as np
import pytest

from rasterize.tracks import Tracks
from riskmap.sim.records import failures
from riskmap.sim.records.failures import (
    MAX_LANES_PER_S,
    adversary_kinematics,
    attack_validity,
    classify_failure,
    collision_fault,
    threat_visible_step,
    unknown_failure,
)

DT = 0.1
LANE = 3.7
SIZE = (5.0, 2.0)


def track(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """States [S, 6] of a vehicle through positions x, y [S] (heading and speed from the motion)."""
    xy = np.column_stack([x, y]).astype(float)
    step = np.diff(xy, axis=0)
    step = np.vstack([step[:1], step])
    speed = np.linalg.norm(step, axis=1) / DT
    heading = np.where(speed[:, None] > 1e-6, step / np.maximum(speed[:, None] * DT, 1e-12), [1.0, 0.0])
    angle = np.unwrap(np.arctan2(heading[:, 1], heading[:, 0]))
    yaw = np.concatenate([[0.0], np.diff(angle) / DT])
    return np.column_stack([xy, heading, speed, yaw])


def braking_x(x0: float, v0: float, decel: float, steps: int, start_s: float = 0.0) -> np.ndarray:
    """Positions at 10 Hz of a vehicle at v0 that brakes at `decel` from `start_s` to a stop."""
    t = DT * np.arange(steps)
    braking = np.clip(t - start_s, 0.0, v0 / decel if decel else np.inf)
    return x0 + v0 * np.minimum(t, start_s) + v0 * braking - 0.5 * decel * braking ** 2


def first_overlap(states: np.ndarray, a: int, b: int) -> int:
    from riskmap.sim.records.metrics import box_iou

    for k in range(states.shape[1]):
        if box_iou(states[a, k], SIZE, states[b, k], SIZE) > 0.02:
            return k
    raise AssertionError("no collision in the hand-built scene")


def scene(*tracks_: np.ndarray) -> Tracks:
    states = np.stack(tracks_)
    return Tracks(states, np.ones(states.shape[:2], bool), np.tile(SIZE, (len(tracks_), 1)),
                  np.zeros(len(tracks_), np.int8))


def smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def test_rear_end_by_a_follower_that_could_not_stop_is_struck_from_behind_and_unavoidable():
    steps = 40
    ego = track(np.full(steps, 50.0), np.zeros(steps))                 # waiting in a queue
    follower = track(15.0 + 20.0 * DT * np.arange(steps), np.zeros(steps))
    tracks = scene(ego, follower)
    k = first_overlap(tracks.states, 0, 1)
    out = classify_failure(tracks, 0, 1, k, DT)
    assert out["fault"] == "struck from behind"
    assert out["avoidable"] is False and out["avoidance"] is None
    assert out["counts"] is False


def test_a_cut_in_the_ego_could_have_braked_for_is_at_fault_and_avoidable():
    steps = 60
    t = DT * np.arange(steps)
    ego = track(20.0 * t, np.zeros(steps))                               # keeps 20 m/s, never brakes
    # A slower car 30 m ahead moves into the ego's lane over 2 s; the ego holds its speed.
    cutter = track(30.0 + 12.0 * t, LANE * (1.0 - smoothstep((t - 0.5) / 2.0)))
    tracks = scene(ego, cutter)
    k = first_overlap(tracks.states, 0, 1)
    out = classify_failure(tracks, 0, 1, k, DT, attack=True, lane_width_m=LANE)
    assert out["fault"] == "at fault"
    assert out["avoidable"] is True and out["avoidance"]["accel_mps2"] < 0      # braking avoids it
    assert out["visible_time_s"] < k * DT - failures.REACTION_S
    assert out["valid_attack"] is True, out["invalid_reasons"]
    assert out["counts"] is True


def test_the_threat_is_visible_only_as_late_as_constant_velocity_predicts_it():
    steps = 80
    t = DT * np.arange(steps)
    ego = track(20.0 * t, np.zeros(steps))
    leader = track(braking_x(50.0, 20.0, 8.0, steps, start_s=3.0), np.zeros(steps))   # 45 m gap, then brakes
    tracks = scene(ego, leader)
    k = first_overlap(tracks.states, 0, 1)
    visible = threat_visible_step(tracks, 0, 1, k)
    assert 30 < visible < k             # not before the leader brakes (equal speeds never meet)
    assert classify_failure(tracks, 0, 1, k, DT)["avoidable"] is True


def test_a_leader_that_brakes_hard_in_a_short_gap_is_unavoidable_for_a_driver_who_must_see_it_first():
    steps = 60
    t = DT * np.arange(steps)
    ego = track(20.0 * t, np.zeros(steps))                      # 15 m behind at equal speed
    leader = track(braking_x(20.0, 20.0, 6.0, steps, start_s=2.5), np.zeros(steps))
    tracks = scene(ego, leader)
    k = first_overlap(tracks.states, 0, 1)
    out = classify_failure(tracks, 0, 1, k, DT)
    assert out["fault"] == "at fault" and out["avoidable"] is False
    # STRIVE's hindsight check, 3 s before the collision whatever the ego could see, finds a way.
    from riskmap.sim.records.alternatives import ego_only_solution

    assert ego_only_solution(tracks, 0, k, DT)


def test_a_threat_that_appears_at_the_collision_leaves_no_time():
    steps = 30
    t = DT * np.arange(steps)
    ego = track(20.0 * t, np.zeros(steps))
    dive = 2 * LANE * (1.0 - smoothstep((t - 2.0) / 0.8))     # across two lanes in 0.8 s, 3 m ahead
    other = track(20.0 * t + 3.0, dive)
    tracks = scene(ego, other)
    k = first_overlap(tracks.states, 0, 1)
    out = classify_failure(tracks, 0, 1, k, DT, attack=True, lane_width_m=LANE)
    assert out["avoidable"] is False
    assert "MAX_LANES_PER_S" in out["invalid_reasons"] and out["valid_attack"] is False


def test_a_sideswipe_from_the_next_lane_is_a_side_contact():
    steps = 40
    t = DT * np.arange(steps)
    ego = track(20.0 * t, np.zeros(steps))
    other = track(20.0 * t + 1.0, LANE * (1.0 - 0.7 * smoothstep((t - 0.5) / 2.0)))
    tracks = scene(ego, other)
    k = first_overlap(tracks.states, 0, 1)
    assert collision_fault(tracks.states[0, k], tracks.states[1, k]) == "side"


def test_an_adversary_that_hits_another_agent_first_is_not_a_valid_attack():
    steps = 60
    t = DT * np.arange(steps)
    ego = track(20.0 * t, np.zeros(steps))
    adversary_y = LANE * 2 * (1.0 - smoothstep((t - 0.5) / 3.0))      # across two lanes in 3 s
    adversary = track(18.0 * t + 8.0, adversary_y)
    bystander = track(20.0 * t + 8.3, np.full(steps, LANE))       # in the middle lane beside it
    tracks = scene(ego, adversary, bystander)
    k = first_overlap(tracks.states, 0, 1)
    out = attack_validity(tracks, 0, 1, k, DT, LANE)
    assert out["hit_agents"] == [2]
    assert "hit another agent" in out["reasons"] and not out["valid"]


@pytest.mark.parametrize("decel, broken", [(6.0, False), (12.0, True)])
def test_braking_beyond_a_cars_grip_breaks_the_braking_limit(decel, broken):
    steps = 40
    kin = adversary_kinematics(track(braking_x(0.0, 25.0, decel, steps, 0.5), np.zeros(steps)), DT, LANE)
    assert kin["min_accel_mps2"] == pytest.approx(-decel, rel=0.05)
    assert ("MAX_BRAKE_MPS2" in failures.kinematic_violations(kin)) is broken


def test_lanes_per_second_of_a_two_second_lane_change_and_of_a_two_lane_dive():
    steps = 60
    t = DT * np.arange(steps)
    one_lane = adversary_kinematics(track(25.0 * t, LANE * smoothstep((t - 1.0) / 2.0)), DT, LANE)
    two_lanes = adversary_kinematics(track(25.0 * t, 2 * LANE * smoothstep((t - 1.0) / 1.0)), DT, LANE)
    assert one_lane["max_lanes_per_s"] < MAX_LANES_PER_S < two_lanes["max_lanes_per_s"]


def test_a_record_without_trajectories_is_unknown_never_guessed():
    out = unknown_failure(attack=True)
    assert out["fault"] == "unknown" and out["avoidable"] is None and out["counts"] is None
    assert out["valid_attack"] is None


def test_the_explanation_says_the_class_and_the_way_out():
    from riskmap.sim.records.failures import failure_explanation, failure_words

    steps = 60
    t = DT * np.arange(steps)
    ego = track(20.0 * t, np.zeros(steps))
    cutter = track(30.0 + 12.0 * t, LANE * (1.0 - smoothstep((t - 0.5) / 2.0)))
    tracks = scene(ego, cutter)
    out = classify_failure(tracks, 0, 1, first_overlap(tracks.states, 0, 1), DT, attack=True,
                           lane_width_m=LANE)
    text = failure_explanation(out)
    assert text.startswith("It counts as a failure of the planner: the other vehicle was ahead")
    assert f"braking at {-out['avoidance']['accel_mps2']:.0f} m/s²" in text and "valid attack" in text
    assert failure_words(out) == "counts: at fault, avoidable, valid attack"
    assert "not classified" in failure_explanation(unknown_failure())


def test_a_crash_flag_without_overlap_finds_the_nearest_box_at_the_last_step():
    from riskmap.sim.records.failures import first_contact

    steps = 20
    t = DT * np.arange(steps)
    ego = track(20.0 * t, np.zeros(steps))
    ahead = track(20.0 * t + 5.8, np.zeros(steps))        # 0.8 m gap: highway-env may flag it
    far = track(20.0 * t + 40.0, np.zeros(steps))
    tracks = scene(ego, ahead, far)
    assert first_contact(tracks, 0) is None
    assert first_contact(tracks, 0, crash_flagged=True) == (steps - 1, 1)


def test_a_highway_env_lane_change_is_valid_under_the_simulators_limits_only():
    from riskmap.sim.records.failures import CAR_LIMITS, HIGHWAY_ENV_LIMITS, kinematic_violations, revalidated

    kin = {"min_accel_mps2": -2.0, "max_accel_mps2": 1.0, "max_lateral_accel_mps2": 11.0,
           "max_yaw_rate_radps": 0.6, "max_lanes_per_s": 0.7}          # what highway-env's MOBIL does
    assert kinematic_violations(kin, CAR_LIMITS) == ["MAX_LATERAL_ACCEL_MPS2"]
    assert kinematic_violations(kin, HIGHWAY_ENV_LIMITS) == []
    stored = {"fault": "at fault", "avoidable": True, "valid_attack": False, "counts": False, "kinematics": kin,
              "invalid_reasons": ["hit another agent", "MAX_LATERAL_ACCEL_MPS2"], "hit_agents": [3]}
    again = revalidated(stored, HIGHWAY_ENV_LIMITS)
    assert again["invalid_reasons"] == ["hit another agent"] and not again["valid_attack"]
    clean = revalidated({**stored, "invalid_reasons": ["MAX_LATERAL_ACCEL_MPS2"]}, HIGHWAY_ENV_LIMITS)
    assert clean["valid_attack"] and clean["counts"] and clean["invalid_reasons"] == []
