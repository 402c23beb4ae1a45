import numpy as np
import pytest

from rasterize.frames import box_corners
from rasterize.geometry import box_gap, boxes_overlap

EAST, NORTH = [1.0, 0.0], [0.0, 1.0]


def test_parallel_boxes_in_line():
    a = box_corners([0, 0], EAST, 5, 2)
    b = box_corners([8, 0], EAST, 5, 2)       # rear of b at 5.5, front of a at 2.5
    assert box_gap(a, b) == pytest.approx(3.0)
    assert not boxes_overlap(a, b)


def test_side_by_side_lanes():
    a = box_corners([0, 0], EAST, 5, 2)
    b = box_corners([1, 4], EAST, 5, 2)       # 4 m apart centre to centre, 2 m wide each
    assert box_gap(a, b) == pytest.approx(2.0)


def test_perpendicular_and_corner_to_corner():
    a = box_corners([0, 0], EAST, 4, 2)       # x in [-2, 2], y in [-1, 1]
    b = box_corners([6, 4], NORTH, 4, 2)      # x in [5, 7], y in [2, 6]
    assert box_gap(a, b) == pytest.approx(np.hypot(3, 1))


def test_overlap_is_zero_gap():
    a = box_corners([0, 0], EAST, 5, 2)
    b = box_corners([2, 0.5], [1, 1], 5, 2)
    assert boxes_overlap(a, b) and box_gap(a, b) == 0.0
