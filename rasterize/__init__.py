"""Scenes, coordinate frames, the BEV rasteriser and the grid maps of the planner.

Knows nothing of torch models: everything here is numpy and OpenCV.
"""

from rasterize.config import (
    ENV_FAMILIES, FAMILY_EXTENTS, Extent, GridConfig, RasterConfig, family_of_env,
    raster_config_for_env,
)
from rasterize.errors import InputError
from rasterize.maps import (
    demo_goal_cell, demo_visitation, goal_map, motion_features, start_cell, uncertainty_map,
)
from rasterize.raster import CHANNELS, rasterize_scene
from rasterize.scene import AgentKind, Lane, LineType, Scene, Signal
from rasterize.tracks import Tracks

__version__ = "0.1.0"

__all__ = [
    "AgentKind", "CHANNELS", "ENV_FAMILIES", "Extent", "FAMILY_EXTENTS", "GridConfig",
    "InputError", "Lane", "LineType", "RasterConfig", "Scene", "Signal", "Tracks", "demo_goal_cell",
    "demo_visitation", "family_of_env", "goal_map", "motion_features", "raster_config_for_env",
    "rasterize_scene", "scene_from_commonroad", "scene_from_highway_env", "start_cell", "uncertainty_map",
]


def __getattr__(name):
    # highway-env (and pygame behind it) load only when a simulator adapter is asked for.
    if name in ("scene_from_highway_env", "TrafficRecorder", "lanes_near"):
        from rasterize import highway

        return getattr(highway, name)
    if name in ("scene_from_commonroad", "RecordedTraffic"):
        # Reading CommonRoad files needs the optional commonroad-io package.
        from rasterize import commonroad

        return getattr(commonroad, name)
    raise AttributeError(name)
