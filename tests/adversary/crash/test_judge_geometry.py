"""Box IoU, off-road fraction and collision types against hand-computed cases."""

import numpy as np
import pytest
from shapely.geometry import Polygon

from adversary.crash.judge import box_iou, classify_collision, drivable_area, off_road_fraction
from rasterize.scene import Lane


def _state(x, y, heading_deg=0.0, speed=10.0):
    a = np.radians(heading_deg)
    return np.array([x, y, np.cos(a), np.sin(a), speed, 0.0])


def test_iou_of_unit_boxes_offset_by_half_a_length_is_one_third():
    size = np.array([1.0, 1.0])
    # overlap 0.5, union 1.5
    assert box_iou(_state(0, 0), size, _state(0.5, 0), size) == pytest.approx(1 / 3, abs=1e-12)
    assert box_iou(_state(0, 0), size, _state(2.0, 0), size) == 0.0
    assert box_iou(_state(0, 0), size, _state(0, 0, 90.0), size) == pytest.approx(1.0, abs=1e-12)


def test_iou_of_rotated_boxes_matches_a_float64_reference():
    a, b = _state(0, 0), _state(1.0, 0.5, 30.0)
    sa, sb = np.array([5.0, 2.0]), np.array([4.0, 1.8])
    # Reference: rotate and intersect the rectangles directly.
    def rect(s, size):
        c, h = s[:2], s[2:4]
        left = np.array([-h[1], h[0]])
        return Polygon([c + sgn_l * size[0] / 2 * h + sgn_w * size[1] / 2 * left
                        for sgn_l, sgn_w in ((1, 1), (1, -1), (-1, -1), (-1, 1))])
    pa, pb = rect(a, sa), rect(b, sb)
    inter = pa.intersection(pb).area
    assert box_iou(a, sa, b, sb) == pytest.approx(inter / (10.0 + 7.2 - inter), rel=1e-12)


def test_off_road_fraction_of_a_box_half_outside_a_lane_is_one_half():
    xs = np.array([0.0, 100.0])
    lane = Lane(np.column_stack([xs, [0, 0]]), np.column_stack([xs, [2, 2]]), np.column_stack([xs, [-2, -2]]))
    area = drivable_area([lane])
    size = np.array([4.0, 2.0])
    assert off_road_fraction(_state(50, 2.0), size, area) == pytest.approx(0.5, abs=1e-12)
    assert off_road_fraction(_state(50, 0.0), size, area) == pytest.approx(0.0, abs=1e-12)
    assert off_road_fraction(_state(50, 10.0), size, area) == pytest.approx(1.0, abs=1e-12)
    assert off_road_fraction(_state(0.0, 0.0), size, area) == pytest.approx(0.5, abs=1e-12)  # lane end


SIZE = np.array([5.0, 2.0])


def _pair(ego, adv, steps=4, adv_before=None):
    """Tracks [K, 6]: both constant, except the adversary's earlier steps if given."""
    ego_track = np.tile(ego, (steps, 1))
    adv_track = np.tile(adv, (steps, 1))
    if adv_before is not None:
        adv_track[:-1] = adv_before
    return ego_track, adv_track


@pytest.mark.parametrize("ego, adv, adv_before, expected", [
    (_state(0, 0), _state(4.8, 0.2), None, "ego rear-ends"),
    (_state(0, 0), _state(-4.8, -0.2), None, "ego rear-ended"),
    (_state(0, 0), _state(4.8, 0.3, 5.0), _state(6.0, 4.0), "cut-in"),     # came from the next lane
    (_state(0, 0), _state(1.0, 1.9), None, "side-swipe"),
    (_state(0, 0), _state(4.9, 0.5, 180.0), None, "head-on"),
    (_state(0, 0), _state(3.0, 3.0, -90.0), None, "T-bone"),
    (_state(0, 0), _state(3.0, -3.0, 65.0), None, "T-bone"),
])
def test_collision_types_of_hand_made_pose_pairs(ego, adv, adv_before, expected):
    assert classify_collision(*_pair(ego, adv, adv_before=adv_before), SIZE, SIZE) == expected


def test_a_car_overtaking_alongside_that_hits_from_behind_is_not_a_cut_in():
    # It was beside the ego but is behind at the collision: side-swipe, not cut-in.
    ego, adv = _pair(_state(0, 0), _state(-1.0, 1.9), adv_before=_state(-3.0, 4.0))
    assert classify_collision(ego, adv, SIZE, SIZE) == "side-swipe"
