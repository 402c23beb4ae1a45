"""Scenes to and from flat arrays, the storage format of dataset shards.

A batch of W scenes packs into fixed-shape arrays padded to the largest agent count, plus ragged
lanes stored as concatenated points with offsets:

    states [W, N, T, 6] float32   valid [W, N, T] bool   sizes [W, N, 2]   kinds [W, N] int8
    ego_index, current_index [W] int16; dt_s, time_s [W] float32
    lane_offsets [W + 1]      lanes of scene w are lane_offsets[w]:lane_offsets[w + 1]
    point_offsets [L + 1]     points of lane l are point_offsets[l]:point_offsets[l + 1]
    lane_centre, lane_left, lane_right [P, 2] float32
    lane_lines [L, 2] int8 (left, right LineType)   lane_width_m, lane_start_s [L] float32
    route_xy [W, K, 2] float32, has_route [W] bool   the ego's route ahead (zeros when unknown)
"""

from __future__ import annotations

import numpy as np

from rasterize.errors import InputError
from rasterize.scene import STATE_DIM, Lane, Scene

SCENE_KEYS = (
    "states", "valid", "sizes", "kinds", "ego_index", "current_index", "dt_s", "time_s",
    "lane_offsets", "point_offsets", "lane_centre", "lane_left", "lane_right", "lane_lines",
    "lane_width_m", "lane_start_s", "route_xy", "has_route",
)


def pack_scenes(scenes: list[Scene]) -> dict[str, np.ndarray]:
    if not scenes:
        raise InputError("pack_scenes needs at least one scene")
    steps = {s.num_steps for s in scenes}
    if len(steps) != 1:
        raise InputError(f"scenes of one shard must share their number of time steps, got {steps}")
    w, t, n = len(scenes), steps.pop(), max(s.num_agents for s in scenes)
    out = {
        "states": np.zeros((w, n, t, STATE_DIM), np.float32),
        "valid": np.zeros((w, n, t), bool),
        "sizes": np.zeros((w, n, 2), np.float32),
        "kinds": np.zeros((w, n), np.int8),
        "ego_index": np.array([s.ego_index for s in scenes], np.int16),
        "current_index": np.array([s.current_index for s in scenes], np.int16),
        "dt_s": np.array([s.dt for s in scenes], np.float32),
        "time_s": np.array([s.time_s for s in scenes], np.float32),
    }
    lanes = [lane for s in scenes for lane in s.lanes]
    for i, s in enumerate(scenes):
        out["states"][i, : s.num_agents] = s.states
        out["valid"][i, : s.num_agents] = s.valid
        out["sizes"][i, : s.num_agents] = s.sizes
        out["kinds"][i, : s.num_agents] = s.kinds
    out["lane_offsets"] = np.cumsum([0] + [len(s.lanes) for s in scenes]).astype(np.int64)
    out["point_offsets"] = np.cumsum([0] + [lane.centre.shape[0] for lane in lanes]).astype(np.int64)
    for key in ("centre", "left", "right"):
        pts = [getattr(lane, key) for lane in lanes]
        out[f"lane_{key}"] = (np.concatenate(pts) if pts else np.zeros((0, 2))).astype(np.float32)
    out["lane_lines"] = np.array([[ln.left_line, ln.right_line] for ln in lanes], np.int8).reshape(-1, 2)
    out["lane_width_m"] = np.array([ln.width_m for ln in lanes], np.float32)
    out["lane_start_s"] = np.array([ln.start_s for ln in lanes], np.float32)
    k = max((len(s.route_xy) for s in scenes if s.route_xy is not None), default=1)
    out["route_xy"] = np.zeros((w, k, 2), np.float32)
    out["has_route"] = np.array([s.route_xy is not None for s in scenes])
    for i, s in enumerate(scenes):
        if s.route_xy is not None:
            if len(s.route_xy) != k:
                raise InputError("scenes of one shard must share their route length")
            out["route_xy"][i] = s.route_xy
    return out


def check_packed(arrays: dict[str, np.ndarray], name: str) -> int:
    """Validate the shapes of packed scenes; returns the number of scenes. `name` is for errors."""
    missing = [k for k in SCENE_KEYS if k not in arrays]
    if missing:
        raise InputError(f"{name}: missing arrays {missing}; re-collect this shard")
    states = arrays["states"]
    if states.ndim != 4 or states.shape[-1] != STATE_DIM or states.shape[0] == 0:
        raise InputError(f"{name}: states have shape {states.shape}, expected [W>0, N, T, 6]")
    w, n, t, _ = states.shape
    expect = {"valid": (w, n, t), "sizes": (w, n, 2), "kinds": (w, n), "ego_index": (w,),
              "current_index": (w,), "dt_s": (w,), "time_s": (w,), "lane_offsets": (w + 1,)}
    for key, shape in expect.items():
        if arrays[key].shape != shape:
            raise InputError(f"{name}: {key} has shape {arrays[key].shape}, expected {shape}")
    n_lanes = int(arrays["lane_offsets"][-1])
    n_points = int(arrays["point_offsets"][-1]) if arrays["point_offsets"].size else 0
    if arrays["point_offsets"].shape != (n_lanes + 1,) or arrays["lane_centre"].shape != (n_points, 2):
        raise InputError(f"{name}: lane arrays are inconsistent; re-collect this shard")
    return w


def unpack_scene(arrays: dict[str, np.ndarray], index: int, source: str = "") -> Scene:
    """Scene `index` of packed arrays (padding agents, which are never valid, are dropped)."""
    valid = arrays["valid"][index]
    present = valid.any(axis=1)
    present[arrays["ego_index"][index]] = True
    keep = np.flatnonzero(present)
    ego = int(arrays["ego_index"][index])
    lanes = []
    po = arrays["point_offsets"]
    for lane in range(arrays["lane_offsets"][index], arrays["lane_offsets"][index + 1]):
        pts = slice(po[lane], po[lane + 1])
        left_line, right_line = arrays["lane_lines"][lane]
        lanes.append(Lane(arrays["lane_centre"][pts], arrays["lane_left"][pts],
                          arrays["lane_right"][pts], int(left_line), int(right_line),
                          float(arrays["lane_width_m"][lane]), float(arrays["lane_start_s"][lane])))
    return Scene(
        states=arrays["states"][index, keep], valid=valid[keep], sizes=arrays["sizes"][index, keep],
        kinds=arrays["kinds"][index, keep], ego_index=int(np.searchsorted(keep, ego)),
        current_index=int(arrays["current_index"][index]), dt=float(arrays["dt_s"][index]),
        lanes=tuple(lanes), source=source, time_s=float(arrays["time_s"][index]),
        route_xy=arrays["route_xy"][index] if arrays["has_route"][index] else None,
    )
