import numpy as np
import pytest

from rasterize.frames import box_corners
from rasterize.geometry import box_gap, boxes_overlap
from rasterize.tracks import Tracks
from riskmap.guard.events import projected_separation, scene_separations

CAR = np.array([5.0, 2.0])  # length, width (m)


def ds(a_xy, a_yaw, b_xy, b_yaw, size_a=CAR, size_b=CAR) -> float:
    return float(projected_separation(np.array(a_xy, float), a_yaw, size_a, np.array(b_xy, float),
                                      b_yaw, size_b))


def test_parallel_in_line_is_gap_between_bumpers():
    # centres 10 m apart along x, both facing x: 10 − (2.5 + 2.5) = 5
    assert ds([0, 0], 0.0, [10, 0], 0.0) == pytest.approx(5.0, abs=1e-12)
    # and then d_s equals the true clearance of the boxes
    a, b = box_corners([0, 0], [1, 0], *CAR), box_corners([10, 0], [1, 0], *CAR)
    assert box_gap(a, b) == pytest.approx(5.0)


def test_parallel_side_by_side_uses_half_widths():
    # 4 m apart sideways: φ = 90° for both, s = w/2 = 1 each → 2
    assert ds([0, 0], 0.0, [0, 4], 0.0) == pytest.approx(2.0, abs=1e-12)


def test_perpendicular():
    # a faces x; b 10 m ahead faces y: s_a = 2.5, s_b = w/2 = 1 → 6.5
    assert ds([0, 0], 0.0, [10, 0], np.pi / 2) == pytest.approx(6.5, abs=1e-12)


def test_diagonal_hand_computed():
    # line of centres at 45°: d = 5√2, s = 2.5·cos45 + 1·sin45 = 3.5/√2 each → 3/√2
    assert ds([0, 0], 0.0, [5, 5], 0.0) == pytest.approx(3.0 / np.sqrt(2.0), abs=1e-12)


def test_overlapping_boxes_are_negative():
    assert ds([0, 0], 0.0, [3, 0], 0.0) == pytest.approx(-2.0, abs=1e-12)
    assert boxes_overlap(box_corners([0, 0], [1, 0], *CAR), box_corners([3, 0], [1, 0], *CAR))
    # coincident centres: −(2.5 + 2.5)
    assert ds([1, 1], 0.3, [1, 1], 0.3) == pytest.approx(-5.0, abs=1e-12)


def test_symmetric_and_broadcasts():
    rng = np.random.default_rng(0)
    a, b = rng.normal(0, 10, (50, 2)), rng.normal(0, 10, (50, 2))
    ya, yb = rng.uniform(-np.pi, np.pi, 50), rng.uniform(-np.pi, np.pi, 50)
    one = projected_separation(a, ya, CAR, b, yb, CAR)
    two = projected_separation(b, yb, CAR, a, ya, CAR)
    assert one.shape == (50,)
    np.testing.assert_allclose(one, two, atol=1e-12)


def test_scene_separations_marks_absent_agents_inf():
    states = np.zeros((3, 2, 6))
    states[..., 2] = 1.0
    states[1, :, 0] = 10.0
    states[2, :, 1] = 4.0
    valid = np.ones((3, 2), bool)
    valid[2, 0] = False
    out = scene_separations(Tracks(states, valid, np.tile(CAR, (3, 1)), np.zeros(3, np.int8)), ego=0)
    assert out.shape == (3, 2)
    assert np.isinf(out[0]).all() and np.isinf(out[2, 0])
    assert out[1, 1] == pytest.approx(5.0) and out[2, 1] == pytest.approx(2.0)


def test_nearest_by_separation_skips_absent_agents_and_keeps_ties_in_order():
    from riskmap.guard.events import nearest_by_separation

    ds = np.array([np.inf, 7.0, 3.0, 7.0, np.inf, -0.5])
    assert nearest_by_separation(ds, 2) == [5, 2]
    assert nearest_by_separation(ds, 4) == [5, 2, 1, 3]          # the tie in index order
    assert nearest_by_separation(ds, 10) == [5, 2, 1, 3]         # never an absent one
    assert nearest_by_separation(np.full(3, np.inf), 2) == []
