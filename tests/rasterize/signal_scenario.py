"""A small synthetic signalised intersection built with commonroad-io objects (no data files).

World metres, x east, y north, time steps of 0.1 s.

    lanelet 1: incoming, centre y = 0 from x = -100 to 0, 3.5 m wide, explicit stop line at
               x = -2; successors 2 (straight on, x 0..50) and 3 (left turn: quarter circle of
               radius 15 about (0, 15), ending at (15, 15) heading north). Lights:
               10 (straight + right): green 0-3 s, amber 3-4 s, red 4-10 s (period 10 s);
               11 (left):             red 0-5 s, green 5-8 s, amber 8-10 s.
    lanelet 4: the lane to its left (centre y = 3.5), no stop line (its end, x = 0, is the
               line); successor 5 (x 0..50). Light 12 (all): red 0-4 s, green 4-9 s, amber
               9-10 s; light 13 on lanelet 4 has no cycle.
    vehicles (4.5 m x 1.8 m, recorded 0-10 s):
               100 straight on along y = 0 at 9 m/s from x = -45 (its front crosses the stop
                   line at 4.53 s: straight is red);
               101 behind it at 10 m/s from x = -60, then the left turn (front crosses at
                   5.575 s: straight red, left green), then straight north;
               102 along lanelet 4 at 10 m/s from x = -80 (front at its line at 7.775 s: green).
"""

from __future__ import annotations

import numpy as np

LENGTH, WIDTH = 4.5, 1.8
STOP_X = -2.0
RADIUS = 15.0


def _straight(y: float, x0: float, x1: float, n: int = 11) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.linspace(x0, x1, n)
    centre = np.column_stack([x, np.full(n, y)])
    return centre + [0, 1.75], centre, centre - [0, 1.75]


def _left_turn(n: int = 19) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    theta = np.linspace(-np.pi / 2, 0.0, n)
    ring = np.column_stack([np.cos(theta), np.sin(theta)])
    centre = np.array([0.0, RADIUS])
    return centre + (RADIUS - 1.75) * ring, centre + RADIUS * ring, centre + (RADIUS + 1.75) * ring


def _cycle(*elements: tuple[str, float]):
    from rasterize.commonroad_compat import TrafficLightCycle, TrafficLightCycleElement, TrafficLightState

    return TrafficLightCycle([TrafficLightCycleElement(TrafficLightState(state), round(s * 10))
                              for state, s in elements], time_offset=0)


def _track(xy: np.ndarray, heading: np.ndarray, speed: np.ndarray):
    from rasterize.commonroad_compat import CustomState, InitialState

    initial = InitialState(position=xy[0], orientation=float(heading[0]), velocity=float(speed[0]),
                           time_step=0, acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
    rest = [CustomState(position=xy[k], orientation=float(heading[k]), velocity=float(speed[k]),
                        time_step=k) for k in range(1, len(xy))]
    return initial, rest


def _vehicle(obstacle_id: int, xy: np.ndarray, heading: np.ndarray, speed: np.ndarray):
    from rasterize.commonroad_compat import (
        DynamicObstacle,
        ObstacleType,
        Trajectory,
        TrajectoryPrediction,
        rect_shape,
    )

    initial, rest = _track(xy, heading, speed)
    shape = rect_shape(length=LENGTH, width=WIDTH)
    return DynamicObstacle(obstacle_id, ObstacleType.CAR, shape, initial,
                           TrajectoryPrediction(Trajectory(1, rest), shape))


def left_turner_xy(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle 101: 10 m/s along y = 0 from x = -60, around the left turn, then north."""
    s = 10.0 * t
    xy, heading = np.zeros((len(t), 2)), np.zeros(len(t))
    arc = 0.5 * np.pi * RADIUS
    straight, turning, north = s <= 60.0, (s > 60.0) & (s <= 60.0 + arc), s > 60.0 + arc
    xy[straight] = np.column_stack([-60.0 + s[straight], np.zeros(straight.sum())])
    angle = (s[turning] - 60.0) / RADIUS - np.pi / 2
    xy[turning] = np.column_stack([RADIUS * np.cos(angle), RADIUS + RADIUS * np.sin(angle)])
    heading[turning] = angle + np.pi / 2
    xy[north] = np.column_stack([np.full(north.sum(), RADIUS), RADIUS + s[north] - 60.0 - arc])
    heading[north] = np.pi / 2
    return xy, heading


def signal_scenario(name: str = "USA_Synth-1_1_T-1", with_uncycled_light: bool = True):
    """The Scenario (module doc)."""
    from rasterize.commonroad_compat import (
        Lanelet,
        LaneletNetwork,
        LineMarking,
        Scenario,
        ScenarioID,
        StopLine,
        TrafficLight,
        TrafficLightDirection,
    )

    scenario = Scenario(0.1, ScenarioID.from_benchmark_id(name, "2020a"))
    network = LaneletNetwork()

    def lanelet(lanelet_id, bounds, successors=(), predecessors=(), stop_line=None, **kw):
        left, centre, right = bounds
        return Lanelet(left, centre, right, lanelet_id, predecessor=list(predecessors),
                       successor=list(successors), stop_line=stop_line, **kw)

    stop = StopLine(np.array([STOP_X, 1.75]), np.array([STOP_X, -1.75]), LineMarking.SOLID)
    network.add_lanelet(lanelet(1, _straight(0.0, -100.0, 0.0), successors=(2, 3), stop_line=stop,
                                adjacent_left=4, adjacent_left_same_direction=True))
    network.add_lanelet(lanelet(2, _straight(0.0, 0.0, 50.0, 6), predecessors=(1,)))
    network.add_lanelet(lanelet(3, _left_turn(), predecessors=(1,)))
    network.add_lanelet(lanelet(4, _straight(3.5, -100.0, 0.0), successors=(5,),
                                adjacent_right=1, adjacent_right_same_direction=True))
    network.add_lanelet(lanelet(5, _straight(3.5, 0.0, 50.0, 6), predecessors=(4,)))
    lights = [
        (TrafficLight(10, np.array([0.0, -3.0]), _cycle(("green", 3), ("yellow", 1), ("red", 6)),
                      direction=TrafficLightDirection.STRAIGHT_RIGHT), {1}),
        (TrafficLight(11, np.array([0.0, -3.0]), _cycle(("red", 5), ("green", 3), ("yellow", 2)),
                      direction=TrafficLightDirection.LEFT), {1}),
        (TrafficLight(12, np.array([0.0, 6.0]), _cycle(("red", 4), ("green", 5), ("yellow", 1)),
                      direction=TrafficLightDirection.ALL), {4}),
    ]
    if with_uncycled_light:
        lights.append((TrafficLight(13, np.array([0.0, 6.0])), {4}))
    for light, lanelets in lights:
        network.add_traffic_light(light, lanelets)
    scenario.add_objects(network)

    t = 0.1 * np.arange(101)
    straight = np.column_stack([-45.0 + 9.0 * t, np.zeros_like(t)])
    scenario.add_objects(_vehicle(100, straight, np.zeros_like(t), np.full_like(t, 9.0)))
    turn_xy, turn_heading = left_turner_xy(t)
    scenario.add_objects(_vehicle(101, turn_xy, turn_heading, np.full_like(t, 10.0)))
    beside = np.column_stack([-80.0 + 10.0 * t, np.full_like(t, 3.5)])
    scenario.add_objects(_vehicle(102, beside, np.zeros_like(t), np.full_like(t, 10.0)))
    return scenario
