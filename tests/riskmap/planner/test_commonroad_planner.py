"""`cr:` SPECs: a CommonRoad planner (commonroad-io's TrajectoryPlannerInterface) drives the ego on
highway-env and on a CommonRoad recording; its 0.1 s Trajectory is tracked at that step, obstacle
ids stay the same across replans, and no solution is counted while the ego brakes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("commonroad")

from commonroad.planning.planner_interface import TrajectoryPlannerInterface  # noqa: E402

from rasterize.commonroad import RecordedTraffic, load_scenario  # noqa: E402
from rasterize.commonroad_compat import CustomState, Trajectory  # noqa: E402
from riskmap.planner.commonroad_planner import CommonRoadPlanner, plan_from_trajectory  # noqa: E402
from riskmap.registry import display_name, make_planner  # noqa: E402
from riskmap.sim.loop.plan import NoSolution, Plan, check_plan  # noqa: E402
from riskmap.sim.loop.plan_checks import implausible_note, plan_problems, summarise_implausible  # noqa: E402
from riskmap.sim.loop.rollout import DriveHooks  # noqa: E402
from riskmap.sim.worlds.commonroad_replay import replay_commonroad_episode  # noqa: E402
from riskmap.sim.worlds.episode import make_env  # noqa: E402
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

HERE = "tests.riskmap.planner.test_commonroad_planner"
RECORDING = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad" / "USA_US101-4_1_T-1.xml"


class TargetSpeedCR(TrajectoryPlannerInterface):
    """Straight on along the ego's heading, easing to `speed_mps` at 1 m/s², 6 s at the scenario's
    0.1 s step; keeps what it was handed."""

    def __init__(self, speed_mps: float = 20.0, fail_after: int = -1, raise_it: bool = False):
        self.speed, self.fail_after, self.raise_it = float(speed_mps), int(fail_after), raise_it
        self.handed = []

    def plan(self, sc, pp, ref_path=None):
        self.handed.append((sc, pp, ref_path))
        if 0 <= self.fail_after < len(self.handed):
            if self.raise_it:
                raise NoSolution("boxed in")
            return None
        start = pp.initial_state
        heading = np.array([np.cos(start.orientation), np.sin(start.orientation)])
        x, v, states = np.asarray(start.position, dtype=np.float64), float(start.velocity), []
        for k in range(1, 61):
            v += float(np.clip(self.speed - v, -0.1, 0.1))
            x = x + v * sc.dt * heading
            states.append(CustomState(time_step=start.time_step + k, position=x.copy(),
                                      orientation=float(start.orientation), velocity=v))
        return Trajectory(start.time_step + 1, states)


def _drive(spec: str, seconds: float = 6.0, hooks: DriveHooks = DriveHooks()):
    planner = make_planner(spec)
    config = DriveConfig("highway-v0", 1, seed=5, episode_s=seconds)
    return planner, drive_episode(make_env("highway-v0"), planner, config, 0, hooks)


def test_cr_spec_wraps_the_factory_and_names_it():
    planner = make_planner(f"cr:{HERE}:TargetSpeedCR?speed_mps=12&predict=toolkit&name=cr12")
    assert isinstance(planner, CommonRoadPlanner) and planner.predict == "toolkit"
    assert planner.planner.speed == 12.0
    assert display_name(f"cr:{HERE}:TargetSpeedCR?predict=none") == "TargetSpeedCR"
    assert display_name(f"cr:{HERE}:TargetSpeedCR?name=mine") == "mine"


def test_highway_drive_tracks_the_trajectory_with_stable_obstacle_ids():
    views = []
    planner = make_planner(f"cr:{HERE}:TargetSpeedCR?speed_mps=18")
    hooks = DriveHooks(on_plan=lambda world, scene, plan, k: views.append((plan, planner.last_view)))
    config = DriveConfig("highway-v0", 1, seed=5, episode_s=8.0)
    record = drive_episode(make_env("highway-v0"), planner, config, 0, hooks)
    assert record["plan_calls"] == 16 and record["no_solution_plans"] == 0
    assert record["implausible_plans"] == 0, record["implausible_plan_first"]
    plan, view = views[0]
    assert plan.dt_s == pytest.approx(0.1) and plan.waypoints.shape == (60, 2) and plan.speeds.shape == (60,)
    assert view.scenario.dt == pytest.approx(0.1)
    assert view.planning_problem.initial_state.time_step == view.time_step == 0
    obstacles = view.scenario.dynamic_obstacles
    assert obstacles and all(len(o.prediction.trajectory.state_list) == 60 for o in obstacles)
    # the road's lanelets: the same ids at every replan, each of the road's 10 km straight lanes
    # cut to the stretch around the scene (a few hundred metres), moving with the ego
    lanelet_ids = [sorted(l.lanelet_id for l in v.scenario.lanelet_network.lanelets) for _, v in views]
    assert lanelet_ids[0] and all(ids == lanelet_ids[0] for ids in lanelet_ids)
    for _, v in (views[0], views[-1]):
        ego_xy = np.asarray(v.planning_problem.initial_state.position)
        for lanelet in v.scenario.lanelet_network.lanelets:
            ends = lanelet.center_vertices[[0, -1]]
            assert 100.0 < np.linalg.norm(ends[1] - ends[0]) < 1000.0
            assert ends[0, 0] < ego_xy[0] < ends[1, 0]
    # one id, one vehicle: where an id is seen at consecutive replans it has moved by its speed
    for (_, a), (_, b) in zip(views, views[1:]):
        before = {o.obstacle_id: o.initial_state for o in a.scenario.dynamic_obstacles}
        for o in b.scenario.dynamic_obstacles:
            if o.obstacle_id in before:
                s = before[o.obstacle_id]
                expected = np.asarray(s.position) + 0.5 * s.velocity * np.array(
                    [np.cos(s.orientation), np.sin(s.orientation)])
                assert np.linalg.norm(np.asarray(o.initial_state.position) - expected) < 3.0
    assert len({o.obstacle_id for _, v in views for o in v.scenario.dynamic_obstacles}) >= 3
    # the ego follows the trajectory's speeds: from highway-env's 25 m/s down to 18 m/s
    assert views[0][1].planning_problem.initial_state.velocity > 20.0
    assert views[-1][1].planning_problem.initial_state.velocity == pytest.approx(18.0, abs=1.5)


@pytest.mark.parametrize("raise_it", [False, True])
def test_no_solution_is_counted_and_the_ego_brakes(raise_it):
    speeds = []
    hooks = DriveHooks(on_step=lambda world: speeds.append(float(world.ego.speed)))
    _, record = _drive(f"cr:{HERE}:TargetSpeedCR?speed_mps=25&fail_after=2&raise_it={str(raise_it).lower()}",
                       seconds=4.0, hooks=hooks)
    assert record["plan_calls"] == 8 and record["no_solution_plans"] == 6
    assert record["no_solution_first"].startswith("at 1.0 s")
    assert ("boxed in" if raise_it else "no trajectory") in record["no_solution_first"]
    # braking from the first failed replan (step 10) on, to a stop at most
    assert all(b <= a + 1e-9 for a, b in zip(speeds[10:], speeds[11:])) and speeds[-1] < speeds[9] - 10.0
    assert min(speeds) >= 0.0
    summary = summarise_implausible([{**record, "episode": 0}], lambda r: f"in episode {r['episode']}")
    assert summary["no_solution_plans"] == 6 and summary["no_solution_episodes"] == 1
    assert "No solution" in implausible_note({"cr": (summary, 1)})


def test_commonroad_recording_hands_over_its_own_lanelets_and_obstacle_ids():
    traffic = RecordedTraffic(load_scenario(RECORDING), RECORDING.stem)
    planner = make_planner(f"cr:{HERE}:TargetSpeedCR?speed_mps=10&predict=none")
    record = replay_commonroad_episode(traffic, 475, planner, duration_s=3.0)
    assert record["plan_calls"] == 6 and record["no_solution_plans"] == 0
    handed = planner.planner.handed
    recorded_lanelets = sorted(l.lanelet_id for l in traffic.scenario.lanelet_network.lanelets)
    recorded_ids = {int(o.obstacle_id) for o in traffic.scenario.dynamic_obstacles}
    types = {int(o.obstacle_id): o.obstacle_type for o in traffic.scenario.dynamic_obstacles}
    for sc, pp, ref_path in handed:
        assert sorted(l.lanelet_id for l in sc.lanelet_network.lanelets) == recorded_lanelets
        assert sc.dynamic_obstacles and all(o.prediction is None for o in sc.dynamic_obstacles)
        assert {o.obstacle_id for o in sc.dynamic_obstacles} <= recorded_ids - {475}
        assert all(o.obstacle_type == types[o.obstacle_id] for o in sc.dynamic_obstacles)
        assert pp.planning_problem_id == 475 and ref_path is not None
    assert len({o.obstacle_id for sc, _, _ in handed for o in sc.dynamic_obstacles}
               & {o.obstacle_id for o in handed[0][0].dynamic_obstacles}) > 0
    steps = [pp.initial_state.time_step for _, pp, _ in handed]
    assert np.diff(steps).tolist() == [5] * 5


def test_trajectories_become_timed_plans_at_their_own_step():
    from rasterize.scene import Scene

    states = np.zeros((1, 1, 6))
    states[0, 0] = [10.0, 5.0, 0.0, 1.0, 4.0, 0.0]              # heading north at 4 m/s
    scene = Scene(states, np.ones((1, 1), bool), np.array([[4.5, 2.0]]), np.zeros(1), 0, 0, 0.5,
                  time_s=3.0)
    every_other = Trajectory(32, [CustomState(time_step=30 + k, position=np.array([10.0, 5.0 + 0.4 * k]),
                                              velocity=4.0) for k in range(2, 21, 2)])
    plan = plan_from_trajectory(every_other, scene, now=30)
    assert plan.dt_s == pytest.approx(0.2) and plan.waypoints.shape == (10, 2)
    np.testing.assert_allclose(plan.waypoints[:, 0], 0.8 * np.arange(1, 11))   # ahead = x in the ego frame
    np.testing.assert_allclose(plan.waypoints[:, 1], 0.0, atol=1e-12)
    assert plan_problems(plan, 4.0) == [] and check_plan(plan, "t") is plan
    with pytest.raises(NoSolution):
        plan_from_trajectory(Trajectory(31, [CustomState(time_step=31, position=np.zeros(2))]), scene, now=31)
    with pytest.raises(NoSolution):
        plan_from_trajectory(None, scene, now=30)


def test_the_classic_form_is_still_exactly_12_by_half_a_second():
    from rasterize.errors import InputError

    ahead = np.stack([5.0 * np.arange(1, 13), np.zeros(12)], axis=1)
    assert not Plan(ahead).timed and plan_problems(Plan(ahead), 10.0) == []
    assert "[12, 2]" in plan_problems(Plan(ahead[:6]), 10.0)[0]
    timed = Plan(ahead[:6], dt_s=0.5, speeds=np.full(6, 10.0))
    assert timed.timed and plan_problems(timed, 10.0) == []
    with pytest.raises(InputError, match="at least 0.1 s"):
        check_plan(Plan(ahead, dt_s=0.05), "t")
    with pytest.raises(InputError, match="Plan.speeds"):
        check_plan(Plan(ahead, dt_s=0.5, speeds=np.ones(3)), "t")
    assert "m/s forward" in plan_problems(Plan(ahead, dt_s=0.5, speeds=-np.ones(12)), 10.0)[0]
