import math

import numpy as np
import pytest

from rasterize.errors import InputError
from rasterize.frames import box_corners
from rasterize.geometry import Polyline, arc_lengths, box_gap, boxes_overlap, drop_repeats

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


# ---- polylines ---------------------------------------------------------------------------------
# References below are plain float64 arithmetic written out here, not the module's code.


def _cumulative(points) -> list[float]:
    out = [0.0]
    for (x0, y0), (x1, y1) in zip(points[:-1], points[1:]):
        out.append(out[-1] + math.hypot(x1 - x0, y1 - y0))
    return out


def test_straight_line():
    line = Polyline(np.array([[0.0, 0.0], [4.0, 0.0], [10.0, 0.0]]))
    np.testing.assert_allclose(line.arc, [0.0, 4.0, 10.0], rtol=0, atol=1e-12)
    assert line.length == pytest.approx(10.0, abs=1e-12)
    s = np.array([-2.0, 0.0, 2.5, 4.0, 7.0, 10.0, 13.0])
    # np.interp semantics: clamped at both ends.
    np.testing.assert_allclose(line.point_at(s), np.stack([np.clip(s, 0, 10), np.zeros(7)], 1), atol=1e-12)
    assert line.point_at(2.5).shape == (2,)
    # Straight on past the end along a given direction, clamped before the start.
    np.testing.assert_allclose(line.point_at(s, beyond=np.array([0.0, 1.0])),
                               [[0, 0], [0, 0], [2.5, 0], [4, 0], [7, 0], [10, 0], [10, 3]], atol=1e-12)
    # pose_at runs straight on past both ends.
    xy, tangent = line.pose_at(s)
    np.testing.assert_allclose(xy, np.stack([s, np.zeros(7)], 1), atol=1e-12)
    np.testing.assert_allclose(tangent, np.tile([1.0, 0.0], (7, 1)), atol=1e-12)
    arc, lateral = line.project(np.array([[3.0, 2.0], [8.0, -1.0], [12.0, 1.0], [-3.0, 0.5]]))
    np.testing.assert_allclose(arc, [3.0, 8.0, 12.0, -3.0], atol=1e-12)
    np.testing.assert_allclose(lateral, [2.0, -1.0, 1.0, 0.5], atol=1e-12)   # left positive
    k, t, distance = line.nearest(np.array([12.0, 1.0]))                       # not run on
    assert (k, t) == (1, 1.0) and distance == pytest.approx(math.hypot(2.0, 1.0), abs=1e-12)
    k, t, distance = line.nearest(np.array([1.0, -3.0]))
    assert (k, t) == (0, pytest.approx(0.25, abs=1e-12)) and distance == pytest.approx(3.0, abs=1e-12)


def test_l_shape():
    points = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]])
    line = Polyline(points)
    np.testing.assert_allclose(line.arc, _cumulative(points.tolist()), atol=1e-12)
    np.testing.assert_allclose(line.arc, [0.0, 3.0, 7.0], atol=1e-12)
    np.testing.assert_allclose(line.segments, [[3.0, 0.0], [0.0, 4.0]], atol=0)
    np.testing.assert_allclose(line.lengths, [3.0, 4.0], atol=1e-12)
    np.testing.assert_allclose(line.point_at([1.0, 3.0, 5.0]), [[1, 0], [3, 0], [3, 2]], atol=1e-12)
    xy, tangent = line.pose_at([1.0, 5.0, 9.0])
    np.testing.assert_allclose(xy, [[1, 0], [3, 2], [3, 6]], atol=1e-12)
    np.testing.assert_allclose(tangent, [[1, 0], [0, 1], [0, 1]], atol=1e-12)     # heading
    arc, lateral = line.project(np.array([[1.0, 1.0], [4.0, 5.0], [2.0, 2.0]]))
    # (4, 5): past the end, on the straight continuation north of (3, 4), 1 m to its right.
    np.testing.assert_allclose(arc, [1.0, 8.0, 5.0], atol=1e-12)
    np.testing.assert_allclose(lateral, [1.0, -1.0, 1.0], atol=1e-12)
    k, t, distance = line.nearest(np.array([4.0, 5.0]))
    assert (k, t) == (1, 1.0) and distance == pytest.approx(math.sqrt(2.0), abs=1e-12)


def test_circle_arc_has_its_analytic_length():
    radius, sweep = 25.0, 0.5 * math.pi                  # a quarter circle, counter-clockwise
    angles = np.linspace(0.0, sweep, 20001)
    points = radius * np.stack([np.cos(angles), np.sin(angles)], 1)
    line = Polyline(points, start_m=100.0)
    # A chord of angle d is 2 r sin(d / 2): the sampled arc falls short by r sweep d^2 / 24.
    assert line.length == pytest.approx(radius * sweep, abs=1e-6)
    assert line.arc[0] == 100.0 and line.arc[-1] == pytest.approx(100.0 + radius * sweep, abs=1e-6)
    np.testing.assert_allclose(arc_lengths(points), np.asarray(_cumulative(points.tolist())), atol=1e-9)
    theta = np.array([0.1, 0.7, 1.3])
    np.testing.assert_allclose(line.point_at(100.0 + radius * theta),
                               radius * np.stack([np.cos(theta), np.sin(theta)], 1), atol=1e-5)
    xy, tangent = line.pose_at(100.0 + radius * theta)
    np.testing.assert_allclose(tangent, np.stack([-np.sin(theta), np.cos(theta)], 1), atol=1e-4)
    outside = (radius + 1.0) * np.stack([np.cos(theta), np.sin(theta)], 1)
    arc, lateral = line.project(outside)
    # Projected onto chords 2 mm long: the arc is exact to a small part of one chord.
    np.testing.assert_allclose(arc, 100.0 + radius * theta, atol=1e-4)
    np.testing.assert_allclose(lateral, -1.0, atol=1e-5)                 # the centre is to the left
    assert line.nearest(outside[1])[2] == pytest.approx(1.0, abs=1e-5)


def test_zero_length_segments():
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [3.0, 0.0], [3.0, 0.0]])
    np.testing.assert_array_equal(arc_lengths(points), [0.0, 1.0, 1.0, 3.0, 3.0])
    line = Polyline(points)                                  # repeats are allowed for point_at
    np.testing.assert_array_equal(line.arc, [0.0, 1.0, 1.0, 3.0, 3.0])
    np.testing.assert_allclose(line.point_at([0.5, 1.0, 2.0, 3.0, 4.0]),
                               [[0.5, 0], [1, 0], [2, 0], [3, 0], [3, 0]], atol=1e-12)
    k, t, distance = line.nearest(np.array([1.0, 2.0]))      # a repeated point: fraction 0
    assert k == 0 and t == 1.0 and distance == pytest.approx(2.0, abs=1e-12)
    kept = drop_repeats(points)
    np.testing.assert_array_equal(kept, [[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]])
    np.testing.assert_array_equal(drop_repeats(np.array([[0.0, 0.0], [1e-7, 0.0], [2.0, 0.0]])),
                                  [[0.0, 0.0], [2.0, 0.0]])
    xy, tangent = Polyline(kept).pose_at([2.0, 5.0])
    np.testing.assert_allclose(xy, [[2.0, 0.0], [5.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(tangent, [[1.0, 0.0], [1.0, 0.0]], atol=1e-12)
    assert len(drop_repeats(np.zeros((4, 2)))) == 1


@pytest.mark.parametrize("points, words", [
    ([[0.0, 0.0]], "N>=2"),
    (np.zeros((0, 2)), "N>=2"),
    ([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], "N>=2"),
    ([0.0, 1.0, 2.0], "N>=2"),
    ([[0.0, 0.0], [np.nan, 1.0], [2.0, 2.0]], "point 1 is NaN or inf"),
    ([[0.0, 0.0], [1.0, np.inf]], "point 1 is NaN or inf"),
])
def test_bad_polylines_are_input_errors(points, words):
    with pytest.raises(InputError) as error:
        Polyline(np.asarray(points, dtype=np.float64))
    message = str(error.value)
    assert words in message and "polyline" in message and "\n" not in message
