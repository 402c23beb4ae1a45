"""commonroad-idm-planner (TUM, PyPI) as a `cr:` ego: the toolkit hands it a CommonRoad
Scenario and PlanningProblem at every replan and tracks the Trajectory it returns.

    cr:commonroad_idm_example:CommonRoadIDM?predict=cv
"""
import logging

from commonroad.planning.planner_interface import TrajectoryPlannerInterface
from commonroad_idm_planner.configuration.planner_config import IDMConfigFactory
from commonroad_idm_planner.idm_path import IDMPathFactory
from commonroad_idm_planner.idm_planner import IDMPlanner
from commonroad_route_planner.fast_api.fast_api import \
    generate_reference_path_from_lanelet_network_and_planning_problem as reference_path


class CommonRoadIDM(TrajectoryPlannerInterface):
    def __init__(self, ignore_static_obstacles: bool = True):
        self.config = IDMConfigFactory().generate_default_config(
            ignore_static_obstacles=ignore_static_obstacles)

    def plan(self, sc, pp, ref_path=None):
        try:
            route = reference_path(lanelet_network=sc.lanelet_network, planning_problem=pp)
        except ValueError:      # the route planner found no route to the goal: no solution
            return None
        path = IDMPathFactory().generate_idm_path_from_cr_route_planner_reference_path(
            cr_reference_path=route)
        # its IDMTrajectory is a commonroad Trajectory at the scenario's 0.1 s step
        return IDMPlanner(scenario=sc, planning_problem=pp, config=self.config, idm_path=path,
                          logging_level=logging.WARNING).plan()
