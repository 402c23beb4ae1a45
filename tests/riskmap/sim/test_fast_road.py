"""riskmap.sim.worlds.fast_road: the same traffic as highway-env's own road, bit for bit.

Each scenario is driven twice from the same seed, on `make_env(fast=False)` and `fast=True`; every
step, every vehicle's position, heading, speed, lanes, action, crash flag and pending impact must
be identical, and so must the recorder's states, the ego's routes, the gaps and the outcome.
"""

import copy

import numpy as np
import pytest

pytest.importorskip("highway_env")

from riskmap.sim.drivers.aggressive import AggressiveParams, install_aggressive_neighbour
from riskmap.sim.drivers.yielding import YieldingDriver
from riskmap.sim.loop.plan import HumanDriver, Plan
from riskmap.sim.loop.rollout import DriveHooks, LoopConfig, drive_world
from riskmap.sim.worlds import fast_road
from riskmap.sim.worlds.episode import Episode, make_env
from riskmap.sim.worlds.fast_road.act_window import _ActWindow
from riskmap.sim.worlds.fast_road.collisions import _collision_candidates
from riskmap.sim.worlds.fast_road.gaps import _min_gap_reference
from riskmap.sim.worlds.fast_road.right_of_way import _rectangles_known


def _bits(x) -> bytes:
    return np.asarray(x, dtype=np.float64).tobytes()


def _vehicle_state(v) -> tuple:
    action = getattr(v, "action", None) or {}
    impact = getattr(v, "impact", None)
    return (type(v).__name__, _bits(v.position), _bits(v.heading), _bits(v.speed), v.lane_index,
            getattr(v, "target_lane_index", None), bool(v.crashed),
            None if impact is None else _bits(impact),
            tuple(sorted((k, _bits(a)) for k, a in action.items())))


def _road_state(run) -> list:
    road = run.base.road
    return [_vehicle_state(v) for v in list(road.vehicles) + list(road.objects)]


def _drive(env_id: str, fast: bool, planner, seed: int, episode: int, seconds: float,
           setup=None, on_ready=()) -> dict:
    run = Episode(make_env(env_id, 10, fast=fast), env_id, seed, episode, setup=setup)
    assert fast_road.is_fast(run.base.road) == fast
    states, scenes = [_road_state(run)], []
    hooks = DriveHooks(on_ready=on_ready, on_step=lambda w: states.append(_road_state(w)),
                       on_plan=lambda w, scene, plan, k: scenes.append(scene))
    loop = drive_world(run, planner, LoopConfig(round(seconds * 10), 5), hooks)
    recorded = run.recorder.tracks()
    crashes = [[v.crashed for v in run.base.road.vehicles]]
    return {"states": states, "recorded": (recorded.states, recorded.valid, recorded.sizes, recorded.kinds),
            "routes": [run.recorder.route_at(k) for k in range(run.recorder.num_steps)],
            "scenes": scenes, "gaps": loop.gaps, "speeds": loop.speeds, "distance": loop.distance_m,
            "crashed": run.crashed, "off_network": run.off_network, "others_crashed": crashes,
            "ego": run.ego}


def _assert_same(plain: dict, fast: dict) -> None:
    assert len(plain["states"]) == len(fast["states"])
    for step, (a, b) in enumerate(zip(plain["states"], fast["states"])):
        assert a == b, f"vehicle states differ at step {step}"
    for a, b in zip(plain["recorded"], fast["recorded"]):
        assert np.array_equal(a, b)
    assert len(plain["routes"]) == len(fast["routes"])
    for a, b in zip(plain["routes"], fast["routes"]):
        assert (a is None and b is None) or np.array_equal(a, b)
    assert len(plain["scenes"]) == len(fast["scenes"])
    for a, b in zip(plain["scenes"], fast["scenes"]):                # what a planner is shown
        _assert_same_scene(a, b)
    assert plain["gaps"] == fast["gaps"] and plain["speeds"] == fast["speeds"]
    assert plain["distance"] == fast["distance"]
    assert (plain["crashed"], plain["off_network"]) == (fast["crashed"], fast["off_network"])
    assert plain["others_crashed"] == fast["others_crashed"]


def _assert_same_scene(a, b) -> None:
    assert np.array_equal(a.states, b.states) and np.array_equal(a.valid, b.valid)
    assert (a.route_xy is None) == (b.route_xy is None)
    assert a.route_xy is None or np.array_equal(a.route_xy, b.route_xy)
    assert len(a.lanes) == len(b.lanes)
    for x, y in zip(a.lanes, b.lanes):
        assert all(np.array_equal(getattr(x, f), getattr(y, f)) for f in ("centre", "left", "right"))
        assert (x.left_line, x.right_line, x.width_m, x.start_s) == \
            (y.left_line, y.right_line, y.width_m, y.start_s)


def _both(env_id, planner_of, seed, episode, seconds, **kwargs) -> tuple[dict, dict]:
    plain = _drive(env_id, False, planner_of(), seed, episode, seconds, **kwargs)
    fast = _drive(env_id, True, planner_of(), seed, episode, seconds, **kwargs)
    _assert_same(plain, fast)
    return plain, fast


class _HoldSpeed:
    """Plans straight ahead at the current speed: drives into whatever stands in its lane."""

    def reset(self, scene) -> None:
        pass

    def plan(self, scene) -> Plan:
        speed = max(float(scene.ego_state()[4]), 15.0)
        return Plan(np.column_stack([speed * 0.5 * np.arange(1, 13), np.zeros(12)]))


def test_highway_traffic_is_the_same():
    plain, _ = _both("highway-v0", HumanDriver, 0, 0, 15.0)
    assert len(plain["states"]) == 151 and len(plain["states"][0]) > 5


def test_intersection_traffic_and_its_crashes_are_the_same():
    plain, _ = _both("intersection-v0", HumanDriver, 1, 0, 10.0)
    assert plain["crashed"]                                    # the ego crashes after 3.6 s
    plain, _ = _both("intersection-v0", HumanDriver, 0, 0, 12.0)
    assert sum(plain["others_crashed"][0]) >= 2                 # two other cars collide


def test_a_planned_ego_driving_into_an_obstacle_is_the_same():
    from highway_env.vehicle.objects import Obstacle

    def obstacle_ahead(base):
        ego = base.vehicle
        lane = base.road.network.get_lane(ego.lane_index)
        s = lane.local_coordinates(ego.position)[0]
        base.road.objects.append(Obstacle(base.road, lane.position(s + 45.0, 0.0)))

    plain, _ = _both("highway-v0", _HoldSpeed, 0, 1, 6.0, setup=obstacle_ahead)
    assert plain["crashed"] and type(plain["ego"]).__name__ == "PlannedVehicle"


def test_an_aggressive_neighbour_is_the_same():
    params = AggressiveParams(selection="softmin", time_gap_s=0.1, brake_gap_m=30.0)
    hooks = (lambda run: install_aggressive_neighbour(run, params),)
    plain, _ = _both("highway-v0", HumanDriver, 2, 0, 10.0, on_ready=hooks)
    assert any(s[0] == "AggressiveVehicle" for s in plain["states"][-1])


def test_a_vehicle_that_decides_on_other_vehicles_is_the_same():
    from highway_env.vehicle.behavior import IDMVehicle

    class Shortsighted(IDMVehicle):
        """Decides as if only the vehicles within 25 m were there, a little closer than they are."""

        def act(self, action=None):
            road, real = self.road, self.road.vehicles
            seen = []
            for v in real:
                if v is not self and np.linalg.norm(v.position - self.position) < 25.0:
                    ghost = copy.copy(v)
                    ghost.position = v.position + 0.8 * (self.position - v.position) / 25.0
                    seen.append(ghost)
            road.vehicles = [self, *seen]
            try:
                super().act(action)
            finally:
                road.vehicles = real

    def shortsighted(base):
        for i, v in enumerate(base.road.vehicles[:6]):
            if v is not base.vehicle:
                base.road.vehicles[i] = Shortsighted.create_from(v)

    plain, _ = _both("highway-v0", HumanDriver, 0, 2, 8.0, setup=shortsighted)
    assert any(s[0] == "Shortsighted" for s in plain["states"][-1])


def test_the_yielding_teacher_merge_and_roundabout_are_the_same():
    _both("intersection-v0", YieldingDriver, 1, 3, 8.0)
    _both("merge-v0", HumanDriver, 0, 0, 8.0)
    plain, _ = _both("roundabout-v0", HumanDriver, 0, 0, 14.0)
    assert plain["crashed"]


def test_scenes_cut_from_a_fast_road_are_the_same():
    rng = np.random.default_rng(4)
    for env_id in ("highway-v0", "intersection-v0", "merge-v0", "roundabout-v0"):
        runs = [Episode(make_env(env_id, 10, fast=fast), env_id, 0, 0) for fast in (False, True)]
        for _ in range(3):
            for run in runs:
                run.step()
            history = float(rng.uniform(0.0, 0.3))
            _assert_same_scene(*(run.scene(history) for run in runs))


def test_the_closest_lane_is_highway_envs_everywhere():
    from highway_env.road.road import RoadNetwork

    rng = np.random.default_rng(0)
    for env_id in ("highway-v0", "intersection-v0", "merge-v0", "roundabout-v0"):
        run = Episode(make_env(env_id, 10, fast=True), env_id, 0, 0)
        network = run.base.road.network
        lanes = [lane for to in network.graph.values() for ls in to.values() for lane in ls]
        for _ in range(1500):
            lane = lanes[rng.integers(len(lanes))]
            s = rng.uniform(-10.0, float(min(lane.length, 500.0)) + 10.0)
            point = lane.position(s, 0.0) + rng.normal(0.0, 3.0, 2)
            heading = None if rng.random() < 0.1 else float(rng.uniform(-4.0, 4.0))
            assert network.get_closest_lane_index(point, heading) == \
                RoadNetwork.get_closest_lane_index(network, point, heading)


def test_the_rectangle_shortcuts_agree_with_highway_env():
    from highway_env import utils

    rng = np.random.default_rng(1)
    decided = 0
    for _ in range(20000):
        p1 = rng.uniform(-3, 3, 2)
        p2 = p1 + rng.uniform(-6, 6, 2)
        r1 = (p1, *rng.uniform(3, 9, 1), *rng.uniform(1, 3, 1), float(rng.uniform(-4, 4)))
        r2 = (p2, *rng.uniform(3, 9, 1), *rng.uniform(1, 3, 1), float(rng.choice([0.0, np.pi / 2, rng.uniform(-4, 4)])))
        known = _rectangles_known(r1, r2, float(np.linalg.norm(p2 - p1)))
        if known is not None:
            decided += 1
            assert known == bool(utils.rotated_rectangles_intersect(r1, r2))
    assert decided > 5000


def test_the_min_gap_is_the_reference_value():
    from riskmap.sim.worlds.episode import min_gap_on_road

    rng = np.random.default_rng(2)
    run = Episode(make_env("highway-v0", 10, fast=True), "highway-v0", 0, 0)
    road, ego = run.base.road, run.ego
    for _ in range(200):
        for v in road.vehicles:
            if v is not ego:
                v.position = ego.position + rng.normal(0.0, 12.0, 2)
                v.heading = float(rng.uniform(-np.pi, np.pi))
        assert min_gap_on_road(road, ego, 40.0) == _min_gap_reference(road, ego, 40.0)


def test_every_pair_highway_env_would_examine_for_a_collision_is_kept():
    from highway_env.vehicle.objects import Obstacle

    rng = np.random.default_rng(3)
    run = Episode(make_env("highway-v0", 10, fast=True), "highway-v0", 0, 0)
    road = run.base.road
    road.objects = [Obstacle(road, [0.0, 0.0]), Obstacle(road, [5.0, 1.0])]
    for _ in range(300):
        for v in road.vehicles + road.objects:
            v.position = rng.uniform(-12.0, 12.0, 2)
            v.speed = float(rng.uniform(-5.0, 30.0))
        vehicles, members = road.vehicles, road.vehicles + road.objects
        kept = _collision_candidates(vehicles, members, 0.1)
        assert kept == sorted(kept)
        examined = [(i, j) for i, v in enumerate(vehicles) for j in range(i + 1, len(members))
                    if not np.linalg.norm(members[j].position - v.position)
                    > (v.diagonal + members[j].diagonal) / 2 + v.speed * 0.1]
        assert set(examined) <= set(kept)


def test_the_switch_and_what_is_upgraded(monkeypatch):
    from highway_env.road.road import Road

    assert type(make_env("highway-v0", 10, fast=False).unwrapped.road) in (type(None), Road)
    env = make_env("highway-v0", 10, fast=True)
    env.reset(seed=0)
    assert fast_road.is_fast(env.unwrapped.road)
    env.reset(seed=1)                                          # every new road is upgraded
    assert fast_road.is_fast(env.unwrapped.road)
    monkeypatch.setenv(fast_road.ENV_VAR, "0")
    env = make_env("highway-v0", 10)
    env.reset(seed=0)
    assert type(env.unwrapped.road) is Road
    twin = copy.deepcopy(env.unwrapped.road)                  # copies keep their class
    assert type(twin) is Road


def test_a_vehicle_that_moves_while_deciding_is_refused():
    from highway_env.vehicle.behavior import IDMVehicle

    class Jumpy(IDMVehicle):
        def act(self, action=None):
            super().act(action)
            self.position = self.position + 1.0

    run = Episode(make_env("highway-v0", 10, fast=True), "highway-v0", 0, 0)
    road = run.base.road
    road.vehicles[1] = Jumpy.create_from(road.vehicles[1])
    with pytest.raises(RuntimeError, match="moved"):
        road.act()


def test_the_neighbour_search_is_highway_envs():
    from highway_env.road.lane import CircularLane, StraightLane
    from highway_env.road.road import Road
    from highway_env.vehicle.objects import Landmark, Obstacle

    rng = np.random.default_rng(5)
    own = (StraightLane.local_coordinates, CircularLane.local_coordinates)
    answers = 0
    for env_id in ("highway-v0", "intersection-v0"):
        run = Episode(make_env(env_id, 10, fast=True), env_id, 0, 0)
        road = run.base.road
        lanes = [(_from, _to, k) for _from, to in road.network.graph.items()
                 for _to, ls in to.items() for k in range(len(ls))]
        road.objects = [Obstacle(road, [0.0, 0.0]), Landmark(road, [5.0, 0.0])]
        for _ in range(40):
            for v in road.vehicles + road.objects:
                lane = road.network.get_lane(lanes[rng.integers(len(lanes))])
                s = float(rng.choice([rng.uniform(-5.0, min(lane.length, 200.0) + 5.0), 10.0]))
                edge = (lane.width_at(s) / 2 + 1) * float(rng.choice([-1.0, 1.0]))  # on_lane's limit
                v.position = lane.position(s, float(rng.choice([0.0, rng.normal(0.0, 2.5), edge])))
            road.vehicles[-1].position = road.vehicles[0].position.copy()      # a tie
            queries = [(v, index) for v in road.vehicles for index in [None, *lanes]]
            expected = [Road.neighbour_vehicles(road, v, index) for v, index in queries]
            window = _ActWindow(road, Landmark, own)            # lanes remember
            try:
                for (v, index), plain in zip(queries, expected):
                    found = window.neighbours(v, index)
                    assert found == plain
                    answers += sum(x is not None for x in found)
            finally:
                window.close()
            assert all("local_coordinates" not in vars(road.network.get_lane(i)) for i in lanes)
    assert answers > 10000


def test_the_right_of_way_pair_test_is_highway_envs(monkeypatch):
    from highway_env.road.regulation import RegulatedRoad

    fast_class = fast_road.FastRegulatedRoad
    fast_test = fast_class.is_conflict_possible
    answers = []

    def both(v1, v2, horizon=3, step=0.25):
        fast, plain = fast_test(v1, v2, horizon, step), RegulatedRoad.is_conflict_possible(v1, v2)
        answers.append((fast, plain))
        return fast

    monkeypatch.setattr(fast_class, "is_conflict_possible", staticmethod(both))
    rng = np.random.default_rng(6)
    for episode in range(3):
        run = Episode(make_env("intersection-v0", 10, fast=True), "intersection-v0", 0, episode)
        for _ in range(30):
            run.step()
            if run.done:
                break
            for v in run.base.road.vehicles:
                if rng.random() < 0.3:
                    v.speed = float(rng.uniform(0.0, 12.0))
            run.base.road.enforce_road_rules()
    assert sum(1 for fast, _ in answers if fast) > 5 and len(answers) > 1000
    assert all(fast is plain for fast, plain in answers)
