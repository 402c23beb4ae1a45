"""Lanelets as `Lane`s (`lanes_from_lanelets`), and the polyline measures the package shares."""

from __future__ import annotations

import numpy as np

from rasterize.geometry import Polyline
from rasterize.scene import Lane, LineType


def _line_type(marking, has_same_direction_neighbour: bool) -> LineType:
    value = getattr(marking, "value", str(marking))
    if value in ("dashed", "broad_dashed", "dashed_dashed"):
        return LineType.DASHED
    if value in ("solid_solid", "broad_solid"):
        return LineType.SOLID_THICK
    if value in ("solid", "solid_dashed", "dashed_solid", "curb", "lowered_curb"):
        return LineType.SOLID
    if value == "no_marking":
        return LineType.NONE
    return LineType.DASHED if has_same_direction_neighbour else LineType.SOLID


def _arc_length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _distance_to_polyline(point: np.ndarray, line: np.ndarray) -> float:
    return Polyline(line).nearest(point)[2]


def _start_arc_lengths(network) -> dict[int, float]:
    """Arc length from the start of each lanelet's chain of first predecessors, so that dashes
    keep their phase across consecutive lanelets."""
    by_id = {ll.lanelet_id: ll for ll in network.lanelets}
    memo: dict[int, float] = {}

    def start(lanelet_id: int, depth: int = 0) -> float:
        if lanelet_id in memo:
            return memo[lanelet_id]
        preds = [p for p in by_id[lanelet_id].predecessor if p in by_id]
        value = 0.0
        if preds and depth < 200:   # depth guards against cycles in odd maps
            first = min(preds)
            value = start(first, depth + 1) + _arc_length(by_id[first].center_vertices)
        memo[lanelet_id] = value
        return value

    return {lanelet_id: start(lanelet_id) for lanelet_id in sorted(by_id)}


def lanes_from_lanelets(network, centre_world: np.ndarray | None = None,
                        radius_m: float = np.inf) -> tuple[Lane, ...]:
    """Every lanelet of a CommonRoad `LaneletNetwork` within `radius_m` of a point, as `Lane`s,
    in increasing lanelet id."""
    starts = _start_arc_lengths(network)
    lanes = []
    for lanelet in sorted(network.lanelets, key=lambda ll: ll.lanelet_id):
        centre = np.asarray(lanelet.center_vertices, dtype=np.float64)
        if centre_world is not None and _distance_to_polyline(np.asarray(centre_world), centre) > radius_m:
            continue
        left = np.asarray(lanelet.left_vertices, dtype=np.float64)
        right = np.asarray(lanelet.right_vertices, dtype=np.float64)
        width = float(np.linalg.norm(left - right, axis=1).mean())
        left_line = _line_type(lanelet.line_marking_left_vertices,
                               lanelet.adj_left is not None and bool(lanelet.adj_left_same_direction))
        right_line = _line_type(lanelet.line_marking_right_vertices,
                                lanelet.adj_right is not None and bool(lanelet.adj_right_same_direction))
        lanes.append(Lane(centre, left, right, left_line, right_line, width,
                          starts[lanelet.lanelet_id]))
    return tuple(lanes)
