"""The commonroad-io API the toolkit uses, for every supported release (2024.3 through 2026.x).

Every import of `commonroad` in the toolkit goes through this module, so that a release which
moves a class changes this file only. Importing it imports commonroad-io (ImportError when that
is not installed): import it inside the functions that need it, as `rasterize.commonroad.reader` does.

What moved between 2024.3 and 2026.1 (the rest of the API used here is the same in both):
- rectangles: 2024.3 has one `commonroad.geometry.shape.Rectangle(length, width, center,
  orientation)` for obstacle shapes and regions alike; 2026.1 splits it into the obstacle's shape
  about its reference point (`commonroad.geometry.obstacle_shapes...RectObstacleShape(width,
  length)`) and a placed region (`commonroad.geometry.occupancy...RectOccupancy`, centred at a
  shapely Point), whose `contains_point` takes a shapely Point instead of an array
  (`rect_shape`, `rect_region`, `region_contains`);
- `ScenarioID` moved from `commonroad.scenario.scenario` to `commonroad.common.common_scenario`.

Only the XML reader and writer are imported, never `CommonRoadFileReader`/`CommonRoadFileWriter`
(`commonroad.common.file_reader`/`file_writer`): those also import the protobuf format, whose
generated modules need the protobuf 3.20 runtime that commonroad-io pins and fail to import under
the newer one tensorboard needs. Recordings come as XML, so nothing is lost.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

import numpy as np
import shapely
from commonroad.common.common_lanelet import LineMarking, StopLine
from commonroad.common.reader.file_reader_xml import XMLFileReader
from commonroad.common.util import Interval
from commonroad.common.writer.file_writer_interface import OverwriteExistingFile
from commonroad.common.writer.file_writer_xml import XMLFileWriter
from commonroad.planning.goal import GoalRegion
from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
from commonroad.prediction.prediction import TrajectoryPrediction
from commonroad.scenario.lanelet import Lanelet, LaneletNetwork, LaneletType
from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType
from commonroad.scenario.scenario import Scenario, Tag
from commonroad.scenario.state import CustomState, InitialState, KSState
from commonroad.scenario.traffic_light import (
    TrafficLight,
    TrafficLightCycle,
    TrafficLightCycleElement,
    TrafficLightDirection,
    TrafficLightState,
)
from commonroad.scenario.trajectory import Trajectory

try:                                   # 2026.1 on
    from commonroad.common.common_scenario import ScenarioID
    from commonroad.geometry.obstacle_shapes.rect_obstacle_shape import RectObstacleShape
    from commonroad.geometry.occupancy.rect_occupancy import RectOccupancy
    SPLIT_SHAPES = True
except ImportError:                    # 2024.3
    from commonroad.geometry.shape import Rectangle
    from commonroad.scenario.scenario import ScenarioID
    SPLIT_SHAPES = False

try:
    COMMONROAD_VERSION = version("commonroad-io")
except PackageNotFoundError:           # an unpacked copy without its metadata
    COMMONROAD_VERSION = "unknown"

__all__ = [
    "COMMONROAD_VERSION", "CustomState", "DynamicObstacle", "GoalRegion", "InitialState", "Interval",
    "KSState", "Lanelet", "LaneletNetwork", "LaneletType", "LineMarking", "ObstacleType",
    "OverwriteExistingFile", "PlanningProblem", "PlanningProblemSet", "Scenario", "ScenarioID",
    "StopLine", "Tag", "TrafficLight", "TrafficLightCycle", "TrafficLightCycleElement",
    "TrafficLightDirection", "TrafficLightState", "Trajectory", "TrajectoryPrediction",
    "XMLFileReader", "XMLFileWriter", "mp_renderer", "rect_region", "rect_shape", "region_contains",
]


def rect_shape(length: float, width: float):
    """An obstacle's rectangle, centred on its position and turned with its orientation."""
    if SPLIT_SHAPES:
        return RectObstacleShape(width=float(width), length=float(length))
    return Rectangle(length=float(length), width=float(width))


def rect_region(center_xy, length: float, width: float, orientation: float):
    """A rectangle placed in the world (a goal region's position)."""
    x, y = (float(v) for v in np.asarray(center_xy, dtype=np.float64).reshape(2))
    if SPLIT_SHAPES:
        return RectOccupancy(rect_center=shapely.Point(x, y), width=float(width), length=float(length),
                             orientation=float(orientation))
    return Rectangle(length=float(length), width=float(width), center=np.array([x, y]),
                     orientation=float(orientation))


def region_contains(region, xy) -> bool:
    """Whether a region read from a file (`rect_region`'s kind) contains the point `xy`."""
    x, y = (float(v) for v in np.asarray(xy, dtype=np.float64).reshape(2))
    return bool(region.contains_point(shapely.Point(x, y) if SPLIT_SHAPES else np.array([x, y])))


def mp_renderer():
    """(MPRenderer, MPDrawParams): imported on demand, as they bring in matplotlib's pyplot."""
    from commonroad.visualization.draw_params import MPDrawParams
    from commonroad.visualization.mp_renderer import MPRenderer

    return MPRenderer, MPDrawParams
