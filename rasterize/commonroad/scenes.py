"""The public entry point: the Scene of a recorded vehicle at a step of a file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rasterize.commonroad.config import CommonRoadSceneConfig
from rasterize.commonroad.reader import load_scenario
from rasterize.commonroad.tracks import RecordedTraffic
from rasterize.errors import InputError
from rasterize.scene import Scene


def scene_from_commonroad(path_or_scenario, ego_id: int, time_index: int,
                          config: CommonRoadSceneConfig = CommonRoadSceneConfig()) -> Scene:
    """The Scene of recorded vehicle `ego_id` at the file's time step `time_index`.

    `path_or_scenario`: a CommonRoad .xml path, a loaded `Scenario`, or a `RecordedTraffic`
    (reuse one when cutting many scenes from a file). History and future are resampled to
    `config.dt_s`; agents without a record at a time are invalid there.
    """
    if isinstance(path_or_scenario, RecordedTraffic):
        traffic = path_or_scenario
    elif isinstance(path_or_scenario, (str, Path)):
        traffic = RecordedTraffic(load_scenario(path_or_scenario), Path(path_or_scenario).stem)
    else:
        traffic = RecordedTraffic(path_or_scenario)
    if not isinstance(time_index, (int, np.integer)):
        raise InputError(f"time index {time_index!r} must be an integer step of the recording")
    return traffic.scene(traffic.index_of(ego_id), int(time_index), config)
