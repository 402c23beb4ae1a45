"""Scenes from recorded traffic in CommonRoad scenario files (NGSIM US-101, I-80, highD, ...).

Files are read with the `commonroad-io` package (releases 2024.3 through 2026.x, through
`rasterize.commonroad_compat`). CommonRoad's world frame is right-handed with x east and y north,
like the toolkit's, so positions and orientations pass through unchanged.

- Lanelets become `Lane`s: centre line and left/right bounds as the file gives them (CommonRoad
  samples both bounds at the same number of vertices, so they line up point by point). Line
  types come from the lanelets' line markings; where the file has none (the 2018b format, or
  `unknown`), a bound shared with a same-direction neighbour is dashed and any other bound is a
  solid road edge, as highway-env paints its roads.
- Dynamic obstacles become agents with their rectangle (or a box around any other shape). Their
  recorded states (at the file's `dt`) are resampled by linear interpolation (heading by its
  unwrapped angle) onto the toolkit's grid of times; times outside a vehicle's record are
  invalid, which is how vehicles entering and leaving the recording show up.
- The ego's route (`Scene.route_xy`) follows the centre line of the lanelet the ego is on and its
  successors, cut by the same goal rule as simulated data (`rasterize.highway.RouteRule`). Where a
  lanelet has several successors (an intersection) the route takes the one the recorded vehicle
  took (`RecordedTraffic.successor_taken`: the successor holding most of its recorded positions;
  the lowest id when its record never reaches one): that is the navigation intent a deployed car
  has, not a position or speed of the recorded future. Where lanelets overlap (inside an
  intersection) the route starts on the one within 45 degrees of the heading that the recorded
  vehicle used most; NGSIM tracks that leave the mapped turning lanelets use one within 3.5 m, and
  with none the route runs straight along the heading (`_lanelet_under`). A lanelet without
  successors ends the route.
- Traffic lights (`LaneletLight`, `lanelet_lights`): every (lanelet, light) pair of the lanelet
  network, at the lanelet's stop line (its `stop_line`, else the segment between the end points of
  its left and right bounds), with the light's cycle. The cycle is periodic, so it continues before
  and beyond the recording. A light forbids passing ("red") in every state but green and inactive:
  amber (yellow) and red-amber count as red. A light without a cycle has no known state: it is
  left out (not drawn, never red) with a one-time warning naming the file and the light.
  `Scene.signals` holds one `Signal` per (lanelet, light) whose stop line lies within the scene's
  extent (`CommonRoadSceneConfig.extent`), with its state every `dt_s` from now to `future_s`.
  Which light governs a vehicle depends on its turn (a light's direction: left, straight, right or
  combinations, `all`); a movement is red when one of the lights governing it is red and none of
  them is green (`movement_red`), so a green right-turn arrow lets a vehicle turn right on red.
- Goal rule at signals (`route_on_lanelets`): while the next signal on the route is red (for the
  route's turn) at the time the ego would reach its stop line (keeping its speed and gaining the
  rule's acceleration up to the limit), the goal point is held `stop_gap_m` (2 m) before the stop
  line, and never so close that the ego's front would be less than 0.5 m from it; once the light
  is green at arrival the goal passes through. A moving ego that cannot stop at the line braking
  3 m/s² (amber caught it) is committed and goes on; a waiting one whose front is past the mapped
  line (NGSIM drivers stop about 2 m past it) is held where it is (`red_light_hold`).

Raster family: recorded highway traffic uses the highway extent (200 m ahead, 40 m behind, 20 m a
side; `rasterize.config.FAMILY_EXTENTS`), so the shipped highway planner reads these scenes as it
reads simulated ones. NGSIM speeds (mostly below 15 m/s) keep the 6 s future well inside it.
Urban recordings (Lankershim) get an extent derived from their own data
(`riskmap.data.collect_commonroad.derive_settings`): less ahead, wide to the sides for turns.

Modules: `reader` (reading a file: `load_scenario`), `config` (`CommonRoadSceneConfig`), `lanes`
(lanelets as `Lane`s), `lights` (traffic lights and the movements they govern), `route` (the
ego's route ahead, held at red lights), `tracks` (`RecordedTraffic`: the recorded vehicles and the
Scene around one of them), `scenes` (`scene_from_commonroad`). The names below are the package's
public ones.
"""

from rasterize.commonroad.config import CommonRoadSceneConfig
from rasterize.commonroad.lanes import lanes_from_lanelets
from rasterize.commonroad.lights import (
    DIRECTION_TURNS,
    GO_STATES,
    TURNS,
    LaneletLight,
    governing,
    lanelet_lights,
    lights_in_extent,
    movement_red,
    turn_between,
)
from rasterize.commonroad.reader import load_scenario
from rasterize.commonroad.route import (
    ALIGNED_COS,
    COMMIT_DECEL_MPS2,
    CREEP_MPS,
    FRONT_MARGIN_M,
    NEAR_LANELET_M,
    red_light_hold,
    route_on_lanelets,
    time_to_cover,
)
from rasterize.commonroad.scenes import scene_from_commonroad
from rasterize.commonroad.tracks import (
    MAX_SPEED_MPS,
    VEHICLE_TYPES,
    RecordedTraffic,
    SetBasedRecording,
    smooth_track,
)

__all__ = [
    "ALIGNED_COS", "COMMIT_DECEL_MPS2", "CREEP_MPS", "DIRECTION_TURNS", "FRONT_MARGIN_M", "GO_STATES",
    "MAX_SPEED_MPS", "NEAR_LANELET_M", "TURNS", "VEHICLE_TYPES", "CommonRoadSceneConfig", "LaneletLight",
    "RecordedTraffic", "SetBasedRecording", "governing", "lanelet_lights", "lanes_from_lanelets",
    "lights_in_extent", "load_scenario", "movement_red", "red_light_hold", "route_on_lanelets",
    "scene_from_commonroad", "smooth_track", "time_to_cover", "turn_between",
]
