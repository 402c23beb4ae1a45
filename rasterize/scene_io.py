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

Traffic lights (`Scene.signals`), ragged twice; optional, since shards written before signals
existed lack them (they unpack with no signals):

    signal_offsets [W + 1]        signals of scene w are signal_offsets[w]:signal_offsets[w + 1]
    signal_stop_line [S, 2, 2] float32
    signal_time_offsets [S + 1]   states of signal i are signal_time_offsets[i]:[i + 1]
    signal_times_s [Q] float64 (seconds from the scene's time), signal_red [Q] bool
"""

from __future__ import annotations

import numpy as np

from rasterize.errors import InputError
from rasterize.scene import STATE_DIM, Lane, Scene, Signal

SCENE_KEYS = (
    "states", "valid", "sizes", "kinds", "ego_index", "current_index", "dt_s", "time_s",
    "lane_offsets", "point_offsets", "lane_centre", "lane_left", "lane_right", "lane_lines",
    "lane_width_m", "lane_start_s", "route_xy", "has_route",
)
# Optional (all or none): older shards have no signals.
SIGNAL_KEYS = ("signal_offsets", "signal_stop_line", "signal_time_offsets", "signal_times_s",
               "signal_red")


def _pack_signals(scenes: list[Scene]) -> dict[str, np.ndarray]:
    signals = [sig for s in scenes for sig in s.signals]
    return {
        "signal_offsets": np.cumsum([0] + [len(s.signals) for s in scenes]).astype(np.int64),
        "signal_stop_line": np.array([sig.stop_line for sig in signals], np.float32).reshape(-1, 2, 2),
        "signal_time_offsets": np.cumsum([0] + [len(sig.times_s) for sig in signals]).astype(np.int64),
        # float64: times a few ms apart must stay increasing.
        "signal_times_s": np.concatenate([sig.times_s for sig in signals] or [np.zeros(0)]),
        "signal_red": np.concatenate([sig.red for sig in signals] or [np.zeros(0, bool)]),
    }


def _unpack_signals(arrays: dict[str, np.ndarray], index: int) -> tuple[Signal, ...]:
    if "signal_offsets" not in arrays:
        return ()
    to = arrays["signal_time_offsets"]
    return tuple(
        Signal(arrays["signal_stop_line"][i], arrays["signal_times_s"][to[i]:to[i + 1]],
               arrays["signal_red"][to[i]:to[i + 1]])
        for i in range(arrays["signal_offsets"][index], arrays["signal_offsets"][index + 1])
    )


def _check_signals(arrays: dict[str, np.ndarray], w: int, name: str) -> None:
    present = [k for k in SIGNAL_KEYS if k in arrays]
    if not present:
        return
    if len(present) != len(SIGNAL_KEYS):
        missing = sorted(set(SIGNAL_KEYS) - set(present))
        raise InputError(f"{name}: signal arrays {missing} are missing; re-collect this shard")
    offsets, times = arrays["signal_offsets"], arrays["signal_time_offsets"]
    n_signals = int(offsets[-1]) if offsets.shape == (w + 1,) else -1
    if (n_signals < 0 or arrays["signal_stop_line"].shape != (n_signals, 2, 2)
            or times.shape != (n_signals + 1,)
            or arrays["signal_times_s"].shape != (int(times[-1]),)
            or arrays["signal_red"].shape != arrays["signal_times_s"].shape):
        raise InputError(f"{name}: signal arrays are inconsistent; re-collect this shard")


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
    out.update(_pack_signals(scenes))
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
    _check_signals(arrays, w, name)
    _check_finite(arrays, name)
    return w


FINITE_KEYS = ("sizes", "dt_s", "time_s", "lane_centre", "lane_left", "lane_right", "lane_width_m",
               "lane_start_s", "route_xy", "signal_stop_line", "signal_times_s")


def _check_finite(arrays: dict[str, np.ndarray], name: str) -> None:
    """NaN or inf in a valid state, a box, a lane or a route is a damaged shard (a Scene would
    refuse it later, naming no file)."""
    bad = arrays["valid"] & ~np.isfinite(arrays["states"]).all(axis=-1)
    if bad.any():
        w, agent, step = (int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"{name}: window {w} holds NaN/inf states (agent row {agent}, step {step}); "
                         "delete the shard and run `riskmap collect ... --resume` to write it again")
    for key in FINITE_KEYS:
        if key in arrays and not np.isfinite(arrays[key]).all():
            raise InputError(f"{name}: {key} holds NaN/inf; delete the shard and run "
                             "`riskmap collect ... --resume` to write it again")


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
        signals=_unpack_signals(arrays, index),
    )
