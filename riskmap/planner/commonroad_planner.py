"""A CommonRoad planner as the ego: SPEC `cr:package.module:Factory?predict=cv&key=value&...`.

The wrapped planner follows commonroad-io's own planner interface,
`commonroad.planning.planner_interface.TrajectoryPlannerInterface` (in commonroad-io 2024.3 and
2026.1 alike): any object with `plan(sc: Scenario, pp: PlanningProblem, ref_path=None) ->
Trajectory` will do. At every replan `CommonRoadPlanner.plan(scene)` hands it

- `sc`, a CommonRoad `Scenario` at STEP_S (0.1 s) steps of what the ego may see: the road's
  lanelet network with its ids (a CommonRoad recording's own network; on a highway-env road,
  lanelets of every lane of the road, `rasterize.commonroad.lanelets`, ids 1 + the lane's index
  in the road, the same at every replan; its straight lanes, 10 km long in highway-env, cut at
  every replan to the stretch the scene's agents, their next HORIZON_S at constant speed and the
  route reach, + `lanelets.LANE_EXTENSION_M` either side, since a planner that samples its reference path
  finely spends seconds on a 10 km lane; without a world, e.g. `riskmap check-planner`'s repeat
  calls, from the scene's lanes), and every other agent of the scene as a `DynamicObstacle` whose id stays the
  same across replans (`Scene.agent_ids`: a recording's obstacle id, or OBSTACLE_ID_OFFSET + the
  highway-env recorder's agent id; a scene without ids numbers its rows after the largest id in
  use), typed as the recording types it, else by size (longer than TRUCK_LENGTH_M: truck), with
  the prediction `predict=` asks for (PREDICTIONS);
- `pp`, the ego's `PlanningProblem`: the world's own (`world.planning_problem(time_step, scene)`
  where the world has one), else a goal GOAL_LENGTH_M x lane width around the end of the route
  ahead (`Scene.route_xy`, the route rule's goal; straight ahead at the current speed for 6 s
  without one), reachable from now to 6 s on; its `InitialState` is the ego's state now;
- `ref_path`: the route ahead [K, 2] (world m), or None;

and the scenario's time step now is round(time_s / STEP_S) (`CommonRoadView.time_step`). The
`Trajectory` it returns becomes a timed `Plan` (`riskmap.sim.loop.plan`): its positions after now, at
its own step, with its speeds where every state has one; the loop tracks it at that step.
A planner that returns None or a trajectory with no state after now, or raises `NoSolution`,
has no plan: the loop counts it (`no_solution_plans`) and brakes.

commonroad-io is imported through `rasterize.commonroad_compat`, inside the functions.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from rasterize.frames import ego_from_world, ego_pose
from rasterize.scene import AgentKind, Scene
from riskmap.sim.loop.plan import NoSolution, Plan

PREDICTIONS = ("none", "cv", "toolkit")
# none: the obstacles' states now only; cv: constant speed along their heading; toolkit: the
# toolkit's own constant speed along their lanes (`rasterize.predict.predict_along_lanes`, what
# the risk maps are drawn from).
STEP_S = 0.1                    # the Scenario's time step (s): the recordings' and the control's
HORIZON_S = 6.0                 # predictions and the goal's time window reach this far (s)
OBSTACLE_ID_OFFSET = 1000       # highway-env: obstacle id = this + recorder agent id (as exported)
TRUCK_LENGTH_M = 7.5            # a vehicle longer than this is a truck (highway-env's trucks: 10 m)
GOAL_LENGTH_M = 10.0            # the goal rectangle along the route
DEFAULT_LANE_WIDTH_M = 4.0


@dataclass(frozen=True, eq=False)
class CommonRoadView:
    """What the wrapped planner was handed at one replan: scenario, planning problem, reference
    path [K, 2] world m (or None), the time step now, and which scene row has which obstacle id
    (row -> id; the ego's row -> the planning problem's id)."""

    scenario: object
    planning_problem: object
    ref_path: np.ndarray | None
    time_step: int
    row_ids: dict


class CommonRoadPlanner:
    """A `TrajectoryPlannerInterface` planner behind the toolkit's planner contract (module
    docstring). `planner`: the wrapped object; `predict`: one of PREDICTIONS."""

    def __init__(self, planner, predict: str = "cv"):
        if predict not in PREDICTIONS:
            raise ValueError(f"predict must be one of {PREDICTIONS}, not {predict!r}")
        self.planner, self.predict = planner, predict
        self.world = None
        self.last_view: CommonRoadView | None = None   # for tests and figures
        self._network = None     # a recording's own lanelet network
        self._lanes = None       # or the lanes of a highway-env road
        self._types: dict[int, object] = {}

    # -- the contract ------------------------------------------------------------------------------

    def reset(self, scene: Scene) -> None:
        self.world, self._network, self._lanes, self._types, self.last_view = None, None, None, {}, None

    def attach(self, world) -> None:
        """Keep the world: its road gives the lanelet network (a recording's, once per episode; a
        highway-env road's lanes, cut at every replan), its recording the obstacles' types, and it
        may give the planning problem (`planning_problem`)."""
        self.world = world
        self._network, self._lanes, self._types = _world_network(world)

    def plan(self, scene: Scene) -> Plan:
        view = self.view(scene)
        trajectory = self.planner.plan(view.scenario, view.planning_problem, view.ref_path)
        return plan_from_trajectory(trajectory, scene, view.time_step)

    # -- what the planner is handed ------------------------------------------------------------

    def view(self, scene: Scene) -> CommonRoadView:
        """The scenario, planning problem and reference path of `scene` (module docstring)."""
        from rasterize.commonroad_compat import Scenario

        now = int(round(scene.time_s / STEP_S))
        network = self._network
        if network is None:
            from rasterize.commonroad.lanelets import lanelets_from_lanes

            if self._lanes is not None:      # the road's lanes, cut to where the scene reaches
                lanelets = lanelets_from_lanes(self._lanes, _reach_xy(scene), cut=True)
            else:
                lanelets = lanelets_from_lanes(scene.lanes, scene.states[:, scene.current_index, :2])
            network = _network_of(lanelets)
        scenario = Scenario(STEP_S)
        scenario.add_objects(copy.deepcopy(network))     # the planner may annotate its copy
        row_ids = _row_ids(scene, self.world, network)
        for row in range(scene.num_agents):
            if row == scene.ego_index or not scene.valid[row, scene.current_index]:
                continue
            scenario.add_objects(self._obstacle(scene, row, row_ids[row], now))
        problem = _world_problem(self.world, now, scene)
        if problem is None:
            problem = route_problem(scene, row_ids[scene.ego_index], now)
        view = CommonRoadView(scenario, problem, scene.route_xy, now, row_ids)
        self.last_view = view
        return view

    def _obstacle(self, scene: Scene, row: int, obstacle_id: int, now: int):
        from rasterize.commonroad_compat import (
            DynamicObstacle,
            ObstacleType,
            Trajectory,
            TrajectoryPrediction,
            rect_shape,
        )

        length, width = (float(v) for v in scene.sizes[row])
        shape = rect_shape(length, width)
        kind = self._types.get(obstacle_id)
        if kind is None:
            if int(scene.kinds[row]) != int(AgentKind.VEHICLE):
                kind = ObstacleType.UNKNOWN
            else:
                kind = ObstacleType.TRUCK if length > TRUCK_LENGTH_M else ObstacleType.CAR
        initial = _initial_state(scene, row, now)
        states = _predicted_states(scene, row, now, self.predict)
        prediction = TrajectoryPrediction(Trajectory(now + 1, states), shape) if states else None
        return DynamicObstacle(int(obstacle_id), kind, shape, initial, prediction)


# -- pieces ----------------------------------------------------------------------------------------

def _network_of(lanelets):
    from rasterize.commonroad_compat import LaneletNetwork

    network = LaneletNetwork()
    for lanelet in lanelets:
        network.add_lanelet(lanelet)
    return network


def _world_network(world) -> tuple:
    """(lanelet network, lanes, {obstacle id: ObstacleType}) of `world`: a recording's own
    network and types; every lane of a highway-env road (its network is built at every replan,
    `_reach_xy`); (None, None, {}) for a world of neither kind."""
    traffic = getattr(world, "traffic", None)
    scenario = getattr(traffic, "scenario", None)
    if scenario is not None:
        types = {int(o.obstacle_id): o.obstacle_type for o in scenario.dynamic_obstacles}
        return copy.deepcopy(scenario.lanelet_network), None, types
    recorder = getattr(world, "recorder", None)
    if recorder is None:
        return None, None, {}
    from rasterize.highway import LaneSampling, lanes_near

    ego_xy = np.asarray(world.ego_state()[:2], dtype=np.float64)
    # every lane of the road, whole, in the network's order: the same ids at every replan
    return None, lanes_near(recorder.road.network, ego_xy, LaneSampling(radius_m=1e6)), {}


def _reach_xy(scene: Scene) -> np.ndarray:
    """[M, 2] world m: where the scene's agents are now and will be in HORIZON_S at constant
    speed, and the route; a highway-env road's straight lanes are cut to this stretch."""
    now = scene.states[scene.valid[:, scene.current_index], scene.current_index]
    ahead = now[:, :2] + HORIZON_S * now[:, 4:5] * now[:, 2:4]
    route = np.zeros((0, 2)) if scene.route_xy is None else np.asarray(scene.route_xy, dtype=np.float64)
    return np.concatenate([now[:, :2], ahead, route.reshape(-1, 2)])


def _row_ids(scene: Scene, world, network) -> dict:
    """Scene row -> CommonRoad obstacle id (module docstring)."""
    recorded = getattr(getattr(world, "traffic", None), "scenario", None) is not None
    if scene.agent_ids is not None:
        offset = 0 if recorded else OBSTACLE_ID_OFFSET
        return {row: offset + int(i) for row, i in enumerate(scene.agent_ids)}
    used = [lanelet.lanelet_id for lanelet in network.lanelets] if network is not None else []
    first = max([OBSTACLE_ID_OFFSET - 1, *used]) + 1
    return {row: first + row for row in range(scene.num_agents)}


def _initial_state(scene: Scene, row: int, now: int):
    from rasterize.commonroad_compat import InitialState

    k = scene.current_index
    x, y, hx, hy, speed, yaw_rate = (float(v) for v in scene.states[row, k])
    before = k > 0 and bool(scene.valid[row, k - 1])
    accel = (speed - float(scene.states[row, k - 1, 4])) / scene.dt if before else 0.0
    return InitialState(time_step=int(now), position=np.array([x, y]), orientation=float(np.arctan2(hy, hx)),
                        velocity=speed, acceleration=float(accel), yaw_rate=yaw_rate, slip_angle=0.0)


def _predicted_states(scene: Scene, row: int, now: int, predict: str) -> list:
    """The prediction's CommonRoad states of scene row `row`, time steps now + 1 ... (PREDICTIONS)."""
    from rasterize.commonroad_compat import CustomState

    if predict == "none":
        return []
    steps = int(round(HORIZON_S / STEP_S))
    times = STEP_S * np.arange(1, steps + 1)
    x, y, hx, hy, speed, _ = scene.states[row, scene.current_index]
    if predict == "cv":
        xy = np.array([x, y]) + times[:, None] * speed * np.array([hx, hy])
        heading = np.tile([hx, hy], (steps, 1))
    else:
        from rasterize.predict import predict_along_lanes

        xy, heading = predict_along_lanes(scene, HORIZON_S, STEP_S)
        xy, heading = xy[row], heading[row]
    return [CustomState(time_step=int(now + 1 + k), position=np.array(xy[k], dtype=np.float64),
                        orientation=float(np.arctan2(heading[k, 1], heading[k, 0])),
                        velocity=float(speed)) for k in range(steps)]


def _world_problem(world, now: int, scene: Scene):
    """The world's own planning problem, where it has one (`planning_problem(time_step, scene)`)."""
    make = getattr(world, "planning_problem", None)
    return make(now, scene) if callable(make) else None


def route_problem(scene: Scene, problem_id: int, now: int):
    """The ego's PlanningProblem from the route rule's goal (module docstring)."""
    from rasterize.commonroad_compat import CustomState, GoalRegion, Interval, PlanningProblem, rect_region

    ego = scene.ego_state()
    route = scene.route_xy
    if route is None or len(route) < 2:
        end = ego[:2] + ego[2:4] * ego[4] * HORIZON_S
        direction = ego[2:4]
    else:
        end = route[-1]
        steps = np.diff(route, axis=0)
        moving = steps[np.linalg.norm(steps, axis=1) > 1e-6]
        direction = moving[-1] if len(moving) else ego[2:4]
    width = (float(np.median([lane.width_m for lane in scene.lanes])) if scene.lanes
             else DEFAULT_LANE_WIDTH_M)
    region = rect_region(end, GOAL_LENGTH_M, width, float(np.arctan2(direction[1], direction[0])))
    goal = GoalRegion([CustomState(time_step=Interval(now, now + int(round(HORIZON_S / STEP_S))),
                                   position=region)])
    return PlanningProblem(int(problem_id), _initial_state(scene, scene.ego_index, now), goal)


def plan_from_trajectory(trajectory, scene: Scene, now: int) -> Plan:
    """The timed `Plan` of a CommonRoad `Trajectory` made at time step `now` (module docstring);
    NoSolution when it holds no state after now. States are taken at their own time steps; a
    trajectory with gaps is interpolated onto its smallest step."""
    states = [] if trajectory is None else list(getattr(trajectory, "state_list", None) or [])
    states = sorted((s for s in states if int(s.time_step) > now), key=lambda s: int(s.time_step))
    if not states:
        raise NoSolution("the planner returned no trajectory" if trajectory is None
                         else "the planner's trajectory holds no state after now")
    steps = np.array([int(s.time_step) - now for s in states])
    steps, first = np.unique(steps, return_index=True)
    states = [states[i] for i in first]
    gap = int(np.diff(np.concatenate([[0], steps])).min())
    grid = np.arange(gap, int(steps[-1]) + 1, gap)
    origin, heading = ego_pose(scene)
    xy = np.array([np.asarray(s.position, dtype=np.float64).reshape(2) for s in states])
    # With the ego now at step 0: a trajectory that starts later is joined to it.
    known = np.concatenate([[0], steps])
    world = np.column_stack([np.interp(grid, known, np.concatenate([[origin[0]], xy[:, 0]])),
                             np.interp(grid, known, np.concatenate([[origin[1]], xy[:, 1]]))])
    speeds = None
    if all(getattr(s, "velocity", None) is not None for s in states):
        v = np.array([float(s.velocity) for s in states])
        speeds = np.interp(grid, known, np.concatenate([[float(scene.ego_state()[4])], v]))
    return Plan(ego_from_world(world, origin, heading), dt_s=round(gap * STEP_S, 9), speeds=speeds)
