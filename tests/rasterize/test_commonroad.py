"""Scenes from CommonRoad recordings, checked against the XML of the two NGSIM US-101 fixtures.

The reference values are read here with the standard library's XML parser, independently of
commonroad-io, so that a mistake in how the adapter uses the package shows up.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("commonroad")

from rasterize.commonroad import (
    CommonRoadSceneConfig,
    RecordedTraffic,
    lanes_from_lanelets,
    load_scenario,
    scene_from_commonroad,
)
from rasterize.errors import InputError
from rasterize.scene import LineType

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "commonroad"
OLD = FIXTURES / "USA_US101-3_3_T-1.xml"      # format 2018b: no line markings, 3.1 s
NEW = FIXTURES / "USA_US101-4_1_T-1.xml"      # format 2020a: line markings, 10 s


def _points(bound) -> np.ndarray:
    return np.array([[float(p.find("x").text), float(p.find("y").text)] for p in bound.iter("point")])


def _xml_lanelets(path: Path) -> dict[int, dict]:
    out = {}
    for lanelet in ET.parse(path).getroot().findall("lanelet"):
        left, right = lanelet.find("leftBound"), lanelet.find("rightBound")
        out[int(lanelet.get("id"))] = {
            "left": _points(left), "right": _points(right),
            "left_marking": getattr(left.find("lineMarking"), "text", None),
            "right_marking": getattr(right.find("lineMarking"), "text", None),
        }
    return out


def _xml_track(path: Path, obstacle_id: int) -> dict[int, tuple[float, float, float, float]]:
    """time step -> (x, y, orientation, velocity) of one dynamic obstacle."""
    for obstacle in ET.parse(path).getroot().iter("dynamicObstacle"):
        if int(obstacle.get("id")) != obstacle_id:
            continue
        track = {}
        for state in [obstacle.find("initialState"), *obstacle.find("trajectory").iter("state")]:
            point = state.find("position").find("point")
            track[int(state.find("time").find("exact").text)] = (
                float(point.find("x").text), float(point.find("y").text),
                float(state.find("orientation").find("exact").text),
                float(state.find("velocity").find("exact").text))
        return track
    raise KeyError(obstacle_id)


@pytest.fixture(scope="module")
def traffic() -> RecordedTraffic:
    return RecordedTraffic(load_scenario(NEW), NEW.stem)


@pytest.mark.parametrize("path", [OLD, NEW], ids=["2018b", "2020a"])
def test_lane_geometry_matches_the_file(path):
    reference = _xml_lanelets(path)
    lanes = lanes_from_lanelets(load_scenario(path).lanelet_network)
    assert len(lanes) == len(reference)
    for lane, lanelet_id in zip(lanes, sorted(reference)):
        ref = reference[lanelet_id]
        np.testing.assert_allclose(lane.left, ref["left"], atol=1e-9)
        np.testing.assert_allclose(lane.right, ref["right"], atol=1e-9)
        np.testing.assert_allclose(lane.centre, 0.5 * (ref["left"] + ref["right"]), atol=1e-9)
        width = np.linalg.norm(ref["left"] - ref["right"], axis=1).mean()
        assert lane.width_m == pytest.approx(width)
        assert 2.5 < lane.width_m < 5.0                      # US-101 lanes are about 3.7 m


def test_line_types_follow_the_markings_or_the_neighbours():
    expected = {"dashed": LineType.DASHED, "solid": LineType.SOLID,
                "broad_solid": LineType.SOLID_THICK}
    reference = _xml_lanelets(NEW)
    lanes = lanes_from_lanelets(load_scenario(NEW).lanelet_network)
    checked = 0
    for lane, lanelet_id in zip(lanes, sorted(reference)):
        for side in ("left", "right"):
            marking = reference[lanelet_id][f"{side}_marking"]
            if marking in expected:
                assert getattr(lane, f"{side}_line") == expected[marking], (lanelet_id, side)
                checked += 1
    assert checked >= 10
    # 2018b has no markings: the leftmost lanelet (31, no left neighbour) gets a solid edge on its
    # left and a dashed line towards its same-direction neighbour 33 on its right.
    old = {ll.lanelet_id: ll for ll in load_scenario(OLD).lanelet_network.lanelets}
    lane_31 = lanes_from_lanelets(load_scenario(OLD).lanelet_network)[sorted(old).index(31)]
    assert (lane_31.left_line, lane_31.right_line) == (LineType.SOLID, LineType.DASHED)


def test_resampled_vehicle_recovers_its_recorded_trajectory(traffic):
    track = _xml_track(NEW, 475)
    scene = scene_from_commonroad(traffic, 475, 40)
    ego = scene.states[scene.ego_index]
    assert scene.valid[scene.ego_index].all() and scene.dt == 0.5
    for k in range(scene.num_steps):          # 2 Hz samples land on every fifth 10 Hz record
        x, y, theta, v = track[40 + 5 * (k - scene.current_index)]
        np.testing.assert_allclose(ego[k, :2], [x, y], atol=1e-9)
        np.testing.assert_allclose(ego[k, 2:4], [np.cos(theta), np.sin(theta)], atol=1e-9)
        assert ego[k, 4] == pytest.approx(v)
    # Between records the state is the linear interpolation: 0.25 s is 2.5 steps of 0.1 s.
    fine = scene_from_commonroad(traffic, 475, 40, CommonRoadSceneConfig(
        history_s=1.0, future_s=1.0, dt_s=0.25))
    x, y = fine.states[0, fine.current_index + 1, :2]
    a, b = np.array(track[42][:2]), np.array(track[43][:2])
    np.testing.assert_allclose([x, y], 0.5 * (a + b), atol=1e-9)
    # Box from the file; the yaw rate is the backward difference of the recorded heading.
    rect = next(o for o in ET.parse(NEW).getroot().iter("dynamicObstacle") if o.get("id") == "475")
    size = [float(rect.find("shape").find("rectangle").find(k).text) for k in ("length", "width")]
    np.testing.assert_allclose(scene.sizes[0], size)
    yaw = (track[40][2] - track[39][2]) / 0.1
    assert scene.states[0, scene.current_index, 5] == pytest.approx(yaw)


def test_vehicles_leaving_are_invalid_after_their_last_record(traffic):
    # Vehicle 381 is recorded for steps 0..37 (0 to 3.7 s); the window of 475 at 2 s spans 0..8 s.
    scene = scene_from_commonroad(traffic, 475, 20)
    agent = [i for i in range(scene.num_agents)
             if np.allclose(scene.states[i, scene.current_index, :2],
                            traffic.states[traffic.index_of(381), 20, :2])]
    assert len(agent) == 1
    times = 2.0 + 0.5 * (np.arange(scene.num_steps) - scene.current_index)
    np.testing.assert_array_equal(scene.valid[agent[0]], times <= 3.7 + 1e-9)
    assert np.isfinite(scene.states).all()


def test_vehicle_entering_is_invalid_before_its_first_record():
    from rasterize.commonroad_compat import (
        DynamicObstacle,
        InitialState,
        KSState,
        ObstacleType,
        Trajectory,
        TrajectoryPrediction,
        rect_shape,
    )

    scenario = load_scenario(NEW)
    # A car entering at step 12 (1.2 s) beside vehicle 475, driving 10 m/s along +x.
    start = RecordedTraffic(scenario).states[RecordedTraffic(scenario).index_of(475), 20, :2] + [0, 8]
    states = [KSState(time_step=k, position=start + [1.0 * (k - 12), 0.0], orientation=0.0,
                      velocity=10.0, steering_angle=0.0) for k in range(13, 60)]
    shape = rect_shape(length=4.0, width=2.0)
    scenario.add_objects(DynamicObstacle(
        9999, ObstacleType.CAR, shape,
        InitialState(time_step=12, position=start, orientation=0.0, velocity=10.0, yaw_rate=0.0,
                     slip_angle=0.0, acceleration=0.0),
        TrajectoryPrediction(Trajectory(13, states), shape)))
    scene = scene_from_commonroad(scenario, 475, 20)
    traffic = RecordedTraffic(scenario)
    here = traffic.states[traffic.index_of(9999), 20, :2]
    agent = next(i for i in range(scene.num_agents)
                 if np.allclose(scene.states[i, scene.current_index, :2], here))
    times = 2.0 + 0.5 * (np.arange(scene.num_steps) - scene.current_index)
    np.testing.assert_array_equal(scene.valid[agent], (times >= 1.2 - 1e-9) & (times <= 5.9 + 1e-9))
    first = int(np.argmax(scene.valid[agent]))               # 1.5 s: 0.3 s after entering
    np.testing.assert_allclose(scene.states[agent, first, :2], start + [3.0, 0.0], atol=1e-9)
    assert tuple(scene.sizes[agent]) == (4.0, 2.0)


def test_route_follows_the_lane_centre_within_the_goal_rule(traffic):
    scene = scene_from_commonroad(traffic, 400, 20)
    route = scene.route_xy
    assert route.shape == (13, 2)
    np.testing.assert_allclose(route[0], scene.ego_state()[:2])
    # Every later point lies on one lanelet centre line (the ego's lane and its successors).
    centres = [lane.centre for lane in scene.lanes]

    def off_centre(p):
        out = np.inf
        for c in centres:
            a, b = c[:-1], c[1:]
            t = np.clip(((p - a) * (b - a)).sum(1) / ((b - a) ** 2).sum(1), 0, 1)
            out = min(out, np.linalg.norm(a + t[:, None] * (b - a) - p, axis=1).min())
        return out

    assert max(off_centre(p) for p in route[2:]) < 0.05   # chords of a 2 m resampling
    speed = scene.ego_state()[4]
    length = np.linalg.norm(np.diff(route, axis=0), axis=1).sum()
    assert 0 < length <= speed * 6 + 0.5 * 6 * 6 + 1.0      # free distance of the route rule


@pytest.mark.parametrize("call, words", [
    (lambda t: scene_from_commonroad(FIXTURES / "missing.xml", 475, 20), "does not exist"),
    (lambda t: scene_from_commonroad(t, 12345, 20), "ego id 12345"),
    (lambda t: scene_from_commonroad(t, 475, 101), "time index 101"),
    (lambda t: scene_from_commonroad(t, 475, -1), "time index -1"),
    (lambda t: scene_from_commonroad(t, 373, 50), "not on the road"),
])
def test_bad_input_raises_one_line_input_error(traffic, call, words):
    with pytest.raises(InputError) as err:
        call(traffic)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_unreadable_file_is_an_input_error(tmp_path):
    bad = tmp_path / "broken.xml"
    bad.write_text("<commonRoad><lanelet id='1'>")
    with pytest.raises(InputError, match="could not be read") as err:
        load_scenario(bad)
    assert "\n" not in str(err.value)


def test_recorded_vehicles_drive_inside_the_lanes(traffic):
    from matplotlib.path import Path as Polygon

    scene = scene_from_commonroad(traffic, 400, 20)
    polygons = [Polygon(lane.polygon()) for lane in scene.lanes]
    now = scene.current_index
    present = np.flatnonzero(scene.valid[:, now])
    inside = [any(p.contains_point(scene.states[a, now, :2]) for p in polygons) for a in present]
    assert len(present) == 18 and all(inside)
