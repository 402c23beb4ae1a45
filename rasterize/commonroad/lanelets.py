"""CommonRoad lanelets from the toolkit's `Lane`s: the road of a highway-env world as CommonRoad sees it.

One builder for every place that shows a highway-env road to CommonRoad tools: the attack export
(`adversary.export.commonroad`) and the CommonRoad planner adapter
(`riskmap.planner.commonroad_planner`). A straight lane is extended along its direction so that
it covers every given position with `extension_m` to spare (highway-env's lanes are long, the
toolkit's stored ones are cut to a scene's extent), and with `cut` also cut to that stretch (the
planner adapter: highway-env's straight lanes are 10 km long, and a planner that samples its
reference path finely spends seconds on each); a curved lane is kept as stored. Bounds are
the centre +- width / 2; two lanelets whose bounds coincide (within 5 cm) are adjacent, in the
same direction. Ids: `id_offset` + the lane's index in the list given. Line markings come from
the lanes' line types.

commonroad-io is imported inside the functions, through `rasterize.commonroad_compat`.
"""

from __future__ import annotations

import numpy as np

LANELET_ID_OFFSET = 1           # lanelet id = this + lane index
LANE_EXTENSION_M = 50.0         # straight lanes reach this far beyond every position given
_ADJACENT_ATOL_M = 0.05         # bounds this close are one shared line
_STRAIGHT_ATOL_M = 1e-3         # a lane whose centre strays less than this from its chord is straight


def is_straight(points: np.ndarray) -> bool:
    """Whether polyline `points` [P, 2] (m) is a straight segment of positive length."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) < 2 or np.linalg.norm(points[-1] - points[0]) < 1e-6:
        return False
    d = (points[-1] - points[0]) / np.linalg.norm(points[-1] - points[0])
    off = (points - points[0]) @ np.array([-d[1], d[0]])
    return bool(np.abs(off).max() < _STRAIGHT_ATOL_M)


def lane_bounds(lanes, positions_xy: np.ndarray, extension_m: float = LANE_EXTENSION_M,
                cut: bool = False) -> list[tuple]:
    """(left, centre, right) polylines [P, 2] (m) of each lane: straight ones extended over
    `positions_xy` [M, 2] (module docstring), curved ones as stored. `cut`: straight ones also
    cut to that stretch (the positions' span + `extension_m` either side), however long the lane."""
    xy = np.asarray(positions_xy, dtype=np.float64).reshape(-1, 2)
    bounds = []
    for lane in lanes:
        centre = np.asarray(lane.centre, dtype=np.float64)
        if is_straight(centre):
            d = (centre[-1] - centre[0]) / np.linalg.norm(centre[-1] - centre[0])
            left_normal = np.array([-d[1], d[0]])
            s = (xy - centre[0]) @ d
            lo = min(0.0, float(s.min()) - extension_m) if len(s) else 0.0
            end = float((centre[-1] - centre[0]) @ d)
            hi = max(end, float(s.max()) + extension_m) if len(s) else end
            if cut and len(s):
                lo, hi = float(s.min()) - extension_m, float(s.max()) + extension_m
            along = centre[0] + np.array([lo, hi])[:, None] * d
            half = 0.5 * lane.width_m
            bounds.append((along + half * left_normal, along, along - half * left_normal))
        else:          # a curved lane: as stored
            bounds.append((np.asarray(lane.left, dtype=np.float64), centre,
                           np.asarray(lane.right, dtype=np.float64)))
    return bounds


def lanelets_from_lanes(lanes, positions_xy: np.ndarray, extension_m: float = LANE_EXTENSION_M,
                        id_offset: int = LANELET_ID_OFFSET, cut: bool = False) -> list:
    """CommonRoad `Lanelet`s of `lanes` (`rasterize.scene.Lane`), covering `positions_xy` [M, 2]
    (module docstring); `cut`: straight lanes cut to that stretch (`lane_bounds`)."""
    from rasterize.commonroad_compat import Lanelet, LaneletType, LineMarking

    markings = {0: LineMarking.NO_MARKING, 1: LineMarking.DASHED, 2: LineMarking.SOLID,
                3: LineMarking.SOLID}
    lanes = list(lanes)
    bounds = lane_bounds(lanes, positions_xy, extension_m, cut)
    lanelets = []
    for i, ((left, centre, right), lane) in enumerate(zip(bounds, lanes)):
        adj_left = adj_right = None
        for j, (other_left, _, other_right) in enumerate(bounds):
            if j == i or len(other_left) != len(left):
                continue
            if np.allclose(other_right, left, atol=_ADJACENT_ATOL_M):
                adj_left = id_offset + j
            if np.allclose(other_left, right, atol=_ADJACENT_ATOL_M):
                adj_right = id_offset + j
        lanelets.append(Lanelet(
            left, centre, right, id_offset + i,
            adjacent_left=adj_left, adjacent_left_same_direction=True if adj_left else None,
            adjacent_right=adj_right, adjacent_right_same_direction=True if adj_right else None,
            line_marking_left_vertices=markings.get(int(lane.left_line), LineMarking.UNKNOWN),
            line_marking_right_vertices=markings.get(int(lane.right_line), LineMarking.UNKNOWN),
            lanelet_type={LaneletType.HIGHWAY}))
    return lanelets
