"""The one scripted aggressive driver (riskmap.sim.drivers.aggressive) on a straight two-lane road."""

import numpy as np
import pytest

from riskmap.sim.drivers.aggressive import AggressiveParams, make_aggressive

pytest.importorskip("highway_env")


def _road_with_ego_and_neighbour(neighbour_x_m: float):
    from highway_env.road.road import Road, RoadNetwork
    from highway_env.vehicle.behavior import IDMVehicle
    from highway_env.vehicle.kinematics import Vehicle

    network = RoadNetwork.straight_road_network(lanes=2, length=2000)
    road = Road(network, np_random=np.random.RandomState(0))
    ego = Vehicle(road, network.get_lane(("0", "1", 0)).position(100, 0), heading=0.0, speed=20.0)
    neighbour = IDMVehicle(road, network.get_lane(("0", "1", 1)).position(neighbour_x_m, 0), heading=0.0,
                           speed=20.0, target_speed=20.0)
    road.vehicles = [ego, neighbour]
    return road, ego, neighbour


def _drive(params: AggressiveParams, neighbour_x_m: float, seconds: float):
    road, ego, neighbour = _road_with_ego_and_neighbour(neighbour_x_m)
    aggressor = make_aggressive(neighbour, lambda: ego, params, dt_s=0.1)
    road.vehicles[1] = aggressor
    trace = []
    for _ in range(int(seconds / 0.1)):
        road.act()
        road.step(0.1)
        trace.append((aggressor.position[0] - ego.position[0], aggressor.lane_index[2], aggressor.speed,
                      aggressor.crashed))
    return np.array(trace)


def test_the_campaign_driver_catches_up_and_pushes_in():
    trace = _drive(AggressiveParams(), neighbour_x_m=80.0, seconds=12.0)
    ahead_m, lane = trace[:, 0], trace[:, 1]
    assert ahead_m[-1] > ahead_m[0]                        # faster than the ego: it catches up
    assert (lane == 0).any()                               # and ends up in the ego's lane


def test_the_guard_script_lines_up_cuts_in_close_and_holds_a_hard_brake():
    params = AggressiveParams(pace_ahead_m=5.0, cut_in_behind_m=0.0, cut_in_ahead_m=8.0,
                              brake_gap_m=15.0, brake_mps2=8.0, brake_hold_s=2.5)
    trace = _drive(params, neighbour_x_m=70.0, seconds=10.0)
    ahead_m, lane, speed, crashed = trace[:, 0], trace[:, 1], trace[:, 2], trace[:, 3].astype(bool)
    first_in_ego_lane = int(np.argmax(lane == 0))
    assert lane[first_in_ego_lane] == 0
    assert 0.0 <= ahead_m[first_in_ego_lane - 1] <= 8.0 + 2.0      # it cut in close ahead of the ego
    decel = -np.diff(speed) / 0.1
    assert decel.max() > 7.5                                        # harder than IDM's 6 m/s² limit
    hard = decel > 7.5
    # one brake check, held for 2.5 s unless it ends in standstill or in the (constant-speed) ego
    # running into it
    runs = np.flatnonzero(np.diff(np.concatenate([[0], hard.astype(int), [0]])) != 0).reshape(-1, 2)
    start, end = runs[0]
    assert len(runs) == 1 and (end - start >= 24 or speed[end] < 0.5 or crashed[end])
