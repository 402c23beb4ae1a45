from types import SimpleNamespace

import numpy as np
import pytest

from rasterize.frames import box_corners
from rasterize.scene import Lane
from riskmap.sim.records.metrics import (
    CAMPAIGN_COLLISION_TYPES,
    COLLISION_TYPES,
    ClosingSafetyConfig,
    SafetyConfig,
    StriveConfig,
    ade_m,
    box_iou,
    box_off_road,
    centre_off_lane,
    classify_collision,
    closing_dangerous_encounters,
    coarse_collision_name,
    coarse_collision_type,
    dangerous_encounters,
    drivable_area,
    goal_error_m,
    mean_jerk_mps3,
    min_box_gap,
    off_road_fraction,
    path_length_m,
    safety_pct,
    summarise_metric,
)


def _states(xy: np.ndarray, heading: float, speed: float) -> np.ndarray:
    """[T, 6] states along positions xy [T, 2] with one heading and speed."""
    t = len(xy)
    return np.column_stack([xy, np.full(t, np.cos(heading)), np.full(t, np.sin(heading)),
                            np.full(t, speed), np.zeros(t)])


def test_ade_and_goal_error_against_a_float64_loop():
    rng = np.random.default_rng(0)
    ego = rng.normal(size=(9, 2)) * 10
    human = rng.normal(size=(9, 2)) * 10
    expected = sum(((ego[i, 0] - human[i, 0]) ** 2 + (ego[i, 1] - human[i, 1]) ** 2) ** 0.5
                   for i in range(9)) / 9
    assert ade_m(ego, human) == pytest.approx(expected, rel=1e-12)
    assert goal_error_m(ego, human) == pytest.approx(np.hypot(*(ego[-1] - human[-1])), rel=1e-12)
    assert ade_m(human, human) == 0.0


def test_an_ego_that_stopped_early_stays_where_it_ended():
    human = np.column_stack([np.arange(5.0) * 10, np.zeros(5)])      # 0, 10, ..., 40 m
    ego = human[:2]                                                  # ended at 10 m after 1 step
    assert ade_m(ego, human) == pytest.approx((0 + 0 + 10 + 20 + 30) / 5)
    assert goal_error_m(ego, human) == pytest.approx(30.0)
    assert ade_m(np.vstack([human, [[50.0, 0.0]]]), human) == 0.0     # extra ego steps do not count


def test_path_length_and_jerk_closed_form():
    # x = t^3 / 6 has jerk exactly 1 m/s^3; 3-4-5 steps are 5 m each.
    dt = 0.1
    t = np.arange(50) * dt
    xy = np.column_stack([t ** 3 / 6.0, np.zeros_like(t)])
    assert mean_jerk_mps3(xy, dt) == pytest.approx(1.0, rel=1e-9)
    steps = np.cumsum(np.tile([[3.0, 4.0]], (5, 1)), axis=0)
    assert path_length_m(np.vstack([[0.0, 0.0], steps])) == pytest.approx(25.0)
    assert mean_jerk_mps3(xy[:3], dt) == 0.0


def _encounter(other_xy, other_heading, other_speed, ego_speed=20.0, steps=1):
    ego = _states(np.zeros((steps, 2)), 0.0, ego_speed)
    other = _states(np.tile(other_xy, (steps, 1)), other_heading, other_speed)[None]
    return dangerous_encounters(ego, np.array([5.0, 2.0]), other, np.ones((1, steps), bool),
                                np.array([[5.0, 2.0]]))


def test_dangerous_encounters_hand_built():
    # Same lane, 0.5 m bumper gap, same speed: too close.
    assert _encounter([5.5, 0.0], 0.0, 20.0) == (1, 1)
    # Adjacent lane (4 m between centres: 2 m clearance), overtaking at +10 m/s: not dangerous,
    # the boxes never meet.
    assert _encounter([0.0, 4.0], 0.0, 30.0) == (0, 1)
    # Same lane, 15 m gap, closing at 20 m/s: contact after 0.75 s < 1.5 s.
    assert _encounter([20.0, 0.0], 0.0, 0.0) == (1, 1)
    # Same lane, 15 m gap, closing at 5 m/s: 3 s away.
    assert _encounter([20.0, 0.0], 0.0, 15.0) == (0, 1)
    # Oncoming in the next lane at a combined 40 m/s: passes without contact.
    assert _encounter([20.0, 4.0], np.pi, 20.0) == (0, 1)
    # Beyond the encounter radius: not an encounter at all.
    assert _encounter([40.0, 0.0], 0.0, 0.0) == (0, 0)
    # Counted per step: three steps of the same close vehicle are three encounters.
    assert _encounter([5.5, 0.0], 0.0, 20.0, steps=3) == (3, 3)


def test_invalid_agents_are_no_encounters_and_config_applies():
    ego = _states(np.zeros((2, 2)), 0.0, 0.0)
    other = _states(np.array([[5.5, 0.0], [5.5, 0.0]]), 0.0, 0.0)[None]
    valid = np.array([[True, False]])
    sizes = np.array([[5.0, 2.0]])
    assert dangerous_encounters(ego, sizes[0], other, valid, sizes) == (1, 1)
    lenient = SafetyConfig(close_gap_m=0.25)
    assert dangerous_encounters(ego, sizes[0], other, valid, sizes, lenient) == (0, 1)
    assert safety_pct(1, 4) == 25.0 and safety_pct(0, 0) == 0.0


def test_summarise_metric_matches_numpy():
    values = [3.0, 1.0, None, 7.0, float("nan"), 2.0]
    s = summarise_metric(values)
    assert s["n"] == 4 and s["mean"] == pytest.approx(3.25)
    assert s["p90"] == pytest.approx(np.percentile([3.0, 1.0, 7.0, 2.0], 90))
    assert summarise_metric([None])["mean"] is None


# ---- box geometry -----------------------------------------------------------------------------

def _box(x: float, y: float, heading: float = 0.0, length: float = 4.0, width: float = 2.0) -> np.ndarray:
    return box_corners(np.array([x, y]), np.array([np.cos(heading), np.sin(heading)]), length, width)


def _state(x: float, y: float, heading: float = 0.0) -> np.ndarray:
    return np.array([x, y, np.cos(heading), np.sin(heading), 0.0, 0.0])


def test_min_box_gap_of_4x2_boxes():
    me = _box(0.0, 0.0)
    # 1 m between the bumpers (centres 5 m apart, half-lengths 2 + 2), 1 m between the sides.
    assert min_box_gap(me, [_box(5.0, 0.0)]) == pytest.approx(1.0, abs=1e-12)
    assert min_box_gap(me, [_box(0.0, 3.0)]) == pytest.approx(1.0, abs=1e-12)
    # Corner to corner: (1, 1) m apart diagonally.
    assert min_box_gap(me, [_box(5.0, 3.0), _box(30.0, 0.0)]) == pytest.approx(np.sqrt(2.0), abs=1e-12)
    assert min_box_gap(me, [_box(1.0, 0.5)]) == 0.0           # overlapping
    assert min_box_gap(me, []) == float("inf")                # nobody near


def test_box_iou_of_4x2_boxes():
    size = np.array([4.0, 2.0])
    assert box_iou(_state(0, 0), size, _state(0, 0), size) == pytest.approx(1.0, abs=1e-12)
    # Shifted by half a length: intersection 2 x 2 = 4 m², union 8 + 8 - 4 = 12 m².
    assert box_iou(_state(0, 0), size, _state(2.0, 0), size) == pytest.approx(4.0 / 12.0, abs=1e-12)
    # Turned by 90 degrees about the same centre: a 2 x 2 square in common, union 12 m².
    assert box_iou(_state(0, 0), size, _state(0, 0, np.pi / 2), size) == pytest.approx(4.0 / 12.0, abs=1e-12)
    assert box_iou(_state(0, 0), size, _state(4.5, 0), size) == 0.0


# ---- off-road ---------------------------------------------------------------------------------

def _lane_area():
    """One straight lane, x in [0, 100] m, y in [-2, 2] m."""
    xs = np.array([0.0, 100.0])
    return drivable_area([Lane(np.column_stack([xs, [0.0, 0.0]]), np.column_stack([xs, [2.0, 2.0]]),
                               np.column_stack([xs, [-2.0, -2.0]]))])


def test_off_road_fraction_and_the_5_percent_rule():
    area, size = _lane_area(), np.array([4.0, 2.0])
    # Box y in [1, 3]: half of it beyond the lane edge at y = 2.
    assert off_road_fraction(_state(50, 2.0), size, area) == pytest.approx(0.5, abs=1e-12)
    assert box_off_road(_state(50, 2.0), size, area)
    # y in [0.2, 2.2]: 0.2 of 2 m off = 10% > 5%; y in [0.05, 2.05]: 2.5% <= 5%.
    assert off_road_fraction(_state(50, 1.2), size, area) == pytest.approx(0.1, abs=1e-12)
    assert box_off_road(_state(50, 1.2), size, area)
    assert off_road_fraction(_state(50, 1.05), size, area) == pytest.approx(0.025, abs=1e-12)
    assert not box_off_road(_state(50, 1.05), size, area)
    assert off_road_fraction(_state(50, 0.0), size, area) == 0.0
    # The threshold is the config's.
    assert box_off_road(_state(50, 1.05), size, area, StriveConfig(off_road_fraction=0.02))


def test_centre_off_lane_uses_the_nearest_lane_and_the_margin():
    class StraightLane:                  # y in [-2, 2] m along x in [0, 100] m
        def on_lane(self, position, margin=0.0):
            return 0.0 <= position[0] <= 100.0 and abs(position[1]) <= 2.0 + margin

    network = SimpleNamespace(get_closest_lane_index=lambda position, heading: ("a", "b", 0),
                              get_lane=lambda index: StraightLane())
    road = SimpleNamespace(network=network)

    def vehicle(x, y):
        return SimpleNamespace(position=np.array([x, y]), heading=0.0)

    assert not centre_off_lane(road, vehicle(50.0, 2.5), margin_m=1.0)     # 0.5 m past the edge
    assert centre_off_lane(road, vehicle(50.0, 3.5), margin_m=1.0)         # 1.5 m past it
    assert centre_off_lane(road, vehicle(50.0, 2.5), margin_m=0.0)


# ---- campaign Safety % ------------------------------------------------------------------------

def _vehicle(x, y, speed, heading=0.0, length=5.0, width=2.0):
    return SimpleNamespace(position=np.array([x, y], float), heading=heading, LENGTH=length, WIDTH=width,
                           velocity=speed * np.array([np.cos(heading), np.sin(heading)]))


def test_closing_dangerous_encounters_hand_built():
    ego = _vehicle(0.0, 0.0, 10.0)

    def count(*others, config=None):
        return closing_dangerous_encounters(ego, [ego, *others], config or ClosingSafetyConfig())

    # 5 m bumper gap, same speed: not closing, gap >= 2 m.
    assert count(_vehicle(10.0, 0.0, 10.0)) == (0, 1)
    # 5 m gap closing at 5 m/s: 1.0 s < 1.5 s.
    assert count(_vehicle(10.0, 0.0, 5.0)) == (1, 1)
    # 5 m gap closing at 2.5 m/s: 2.0 s.
    assert count(_vehicle(10.0, 0.0, 7.5)) == (0, 1)
    # Next lane, 1.5 m between the sides: under 2 m, dangerous although nobody closes.
    assert count(_vehicle(0.0, 3.5, 10.0)) == (1, 1)
    # Radius: exactly 40 m counts, 41 m does not.
    assert count(_vehicle(40.0, 0.0, 10.0), _vehicle(41.0, 0.0, 10.0)) == (0, 1)
    assert count(_vehicle(0.0, 3.5, 10.0), config=ClosingSafetyConfig(close_gap_m=1.0)) == (0, 1)


# ---- collision types --------------------------------------------------------------------------

def test_fine_and_coarse_collision_types():
    size = np.array([5.0, 2.0])
    ego = np.tile(_state(0.0, 0.0), (2, 1))

    def fine(x, y, heading):
        return classify_collision(ego, np.tile(_state(x, y, heading), (2, 1)), size, size)

    def coarse(x, y, heading):
        return coarse_collision_type(_vehicle(0.0, 0.0, 0.0), _vehicle(x, y, 0.0, heading))

    assert fine(4.0, 0.0, 0.0) == coarse(4.0, 0.0, 0.0) == "ego rear-ends"
    assert fine(-4.0, 0.0, 0.0) == coarse(-4.0, 0.0, 0.0) == "ego rear-ended"
    assert fine(4.0, 0.0, np.pi) == coarse(4.0, 0.0, np.pi) == "head-on"
    assert fine(2.0, 2.0, np.pi / 2) == "T-bone" and coarse(2.0, 2.0, np.pi / 2) == "side (angle)"
    # The two classifiers' thresholds differ: at 130 degrees the fine one says head-on.
    assert fine(3.0, 1.0, np.radians(130)) == "head-on"
    assert coarse(3.0, 1.0, np.radians(130)) == "side (angle)"
    # The fine labels in the campaign's vocabulary.
    assert [coarse_collision_name(t) for t in COLLISION_TYPES] == [
        "ego rear-ends", "ego rear-ended", "cut-in", "sideswipe", "head-on", "side (angle)"]
    assert coarse_collision_name(None) is None
    assert set(map(coarse_collision_name, COLLISION_TYPES)) == set(CAMPAIGN_COLLISION_TYPES)
