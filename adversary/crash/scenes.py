"""Attack scenes: a recorded human episode and the 2 Hz window an adversary is generated in.

An `AttackScene` names episode `episode` of `riskmap drive --seed scene_seed` on `env_id`,
attacked at `t0_s`. `record_attack_scene` drives the IDM/MOBIL human ego on it for
t0 + horizon seconds (`riskmap.sim.worlds.log_replay.record_human_episode`, 10 Hz) and cuts the window the
traffic model sees: 2 s of history and `horizon_s` of logged future at 2 Hz (4 + 1 + 12 = 17
steps for the defaults, current index 4), the ego in row 0 and then the others within `radius_m`
nearest first, at most `max_agents` rows, with the lanes around the ego, exactly as
`TrafficRecorder.scene` builds a scene. `agent_ids[row]` is the HumanLog agent of each row.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rasterize.config import family_of_env
from rasterize.errors import InputError
from rasterize.scene import Lane, LineType, Scene
from rasterize.timebase import CONTROL_HZ, FUTURE_S, HISTORY_S, PLAN_DT_S
from riskmap.infra.atomic import write_json, write_npz
from riskmap.sim.drivers.static_agents import MAX_STATIC_AGENTS, STATIC_FAMILIES
from riskmap.sim.worlds.episode import cached_env
from riskmap.sim.worlds.log_replay import HumanLog

WINDOW_DT_S = PLAN_DT_S    # the traffic model's step (2 Hz)
# CONTROL_HZ (rasterize.timebase, 10): the recorded logs' rate, and every attack drive's control rate.
# HISTORY_S (rasterize.timebase, 2 s): past the window shows (4 steps before the current one).
RECORDED_ENV = "commonroad"  # env_id of a scene cut from a CommonRoad recording (adversary.crash.recorded)

@dataclass(frozen=True)
class AttackScene:
    """Episode `episode` of `riskmap drive --seed scene_seed` on `env_id`, attacked at `t0_s`."""

    env_id: str
    scene_seed: int
    episode: int
    t0_s: float = 2.0          # attack time; at least HISTORY_S so the window has its history
    horizon_s: float = FUTURE_S  # generated future after t0 (12 steps at 2 Hz)
    static_agents: int = 0     # parked / stopped vehicles added to the simulated episode
    recording: str = ""        # a CommonRoad recording (.xml) instead of a highway-env episode:
    ego_id: int = -1           # then the recorded vehicle attacked as the ego (its obstacle id)

    @property
    def future_steps(self) -> int:
        """Window steps after the current one (12 for the default horizon)."""
        return round(self.horizon_s / WINDOW_DT_S)

    @property
    def where(self) -> str:
        """The scene in words (titles, messages)."""
        if self.recording:
            return f"{Path(self.recording).stem} vehicle {self.ego_id}"
        return f"{self.env_id} seed {self.scene_seed} episode {self.episode}"

    def check(self, control_hz: int) -> None:
        if self.recording or self.env_id == RECORDED_ENV:
            if self.env_id != RECORDED_ENV or not self.recording or self.ego_id < 0:
                raise InputError(f"a recorded scene needs env_id {RECORDED_ENV!r}, a recording and an "
                                 f"ego_id >= 0 (got {self.env_id!r}, {self.recording!r}, {self.ego_id}); "
                                 "record it with `adversary scenes --commonroad`")
        else:
            family = family_of_env(self.env_id)      # InputError naming the supported envs
            if self.static_agents and family not in STATIC_FAMILIES:
                raise InputError(f"static vehicles are placed on {', '.join(STATIC_FAMILIES)} scenes only, "
                                 f"not on {self.env_id}; use static_agents=0 (--static-agents 0)")
        if (not 0 <= self.static_agents <= MAX_STATIC_AGENTS
                or (self.static_agents and (self.recording or self.env_id == RECORDED_ENV))):
            raise InputError(f"static_agents={self.static_agents} must be 0 to {MAX_STATIC_AGENTS}, and 0 for "
                             "a recorded scene (its vehicles are the recording's); change --static-agents")
        if self.t0_s < HISTORY_S - 1e-9:
            raise InputError(f"attack time t0_s={self.t0_s} leaves less than {HISTORY_S} s of history; "
                             f"use t0_s >= {HISTORY_S}")
        for name, value in (("t0_s", self.t0_s), ("horizon_s", self.horizon_s)):
            if (not np.isfinite(value) or value <= 0
                    or abs(value / WINDOW_DT_S - round(value / WINDOW_DT_S)) > 1e-9):
                raise InputError(f"{name}={value} must be a positive multiple of {WINDOW_DT_S} s")
        if control_hz <= 0 or abs(control_hz * WINDOW_DT_S - round(control_hz * WINDOW_DT_S)) > 1e-9:
            raise InputError(f"control_hz={control_hz} must be a multiple of {1 / WINDOW_DT_S:g} Hz")


@dataclass(frozen=True, eq=False)
class SceneRecord:
    """A recorded attack scene (module docstring). log: the human's 10 Hz record up to t0 +
    horizon; window: the 2 Hz Scene at t0; agent_ids [N]: log agent of each window row."""

    scene: AttackScene
    log: HumanLog
    window: Scene
    agent_ids: np.ndarray
    family: str = ""           # recorded scenes: their traffic-model family (us101, lankershim, ...)

    @property
    def t0_step(self) -> int:
        """The log step of t0."""
        return round(self.scene.t0_s / self.log.dt_s)

    @property
    def stride(self) -> int:
        """Log steps per window step."""
        return round(WINDOW_DT_S / self.log.dt_s)


def window_rows(log: HumanLog, step: int, radius_m: float, max_agents: int) -> np.ndarray:
    """Log agents of the window at `step`: the ego, then the others present within `radius_m`
    nearest first, at most `max_agents` in all (TrafficRecorder.scene's selection)."""
    ego = log.ego_id
    ego_xy = log.states[ego, step, :2]
    others = [a for a in np.flatnonzero(log.valid[:, step]) if a != ego]
    dist = np.array([np.linalg.norm(log.states[a, step, :2] - ego_xy) for a in others])
    order = [others[i] for i in np.argsort(dist, kind="stable") if dist[i] <= radius_m]
    return np.array([ego] + order[: max_agents - 1], dtype=np.int64)


def window_of(log: HumanLog, agent_ids: np.ndarray, step: int, future_steps: int,
              lanes: tuple[Lane, ...], route_xy: np.ndarray | None, source: str) -> Scene:
    """The 2 Hz Scene of `agent_ids` around log `step` (times outside the log are invalid)."""
    stride = round(WINDOW_DT_S / log.dt_s)
    n_hist = round(HISTORY_S / WINDOW_DT_S)
    times = step + stride * np.arange(-n_hist, future_steps + 1)
    inside = (times >= 0) & (times < log.num_steps)
    clipped = np.clip(times, 0, log.num_steps - 1)
    return Scene(log.states[agent_ids][:, clipped], log.valid[agent_ids][:, clipped] & inside[None, :],
                 log.sizes[agent_ids], log.kinds[agent_ids], ego_index=0, current_index=n_hist,
                 dt=WINDOW_DT_S, lanes=lanes, source=source, time_s=step * log.dt_s, route_xy=route_xy)


def record_attack_scene(scene: AttackScene, control_hz: int = CONTROL_HZ, radius_m: float = 60.0,
                        max_agents: int = 12, env=None) -> SceneRecord:
    """Drive the human on `scene` for t0 + horizon and cut its window (module docstring).

    InputError if the scene cannot be attacked: a bad env or times, the human crashed or left the
    road before t0 + horizon, or no other vehicle is within `radius_m` of the ego at t0 (callers
    that sweep episodes skip those).
    """
    from riskmap.sim.worlds.episode import Episode
    from riskmap.sim.worlds.log_replay import log_of

    scene.check(control_hz)
    if max_agents < 2 or radius_m <= 0:
        raise InputError(f"max_agents={max_agents} must be >= 2 and radius_m={radius_m} positive")
    env = cached_env(scene.env_id, control_hz) if env is None else env
    run = Episode(env, scene.env_id, scene.scene_seed, scene.episode, control_hz,
                  static_agents=scene.static_agents)
    total = round((scene.t0_s + scene.horizon_s) * control_hz)
    for _ in range(total):
        run.step()
        if run.done:
            break
    log = log_of(run)
    where = f"{scene.env_id} seed {scene.scene_seed} episode {scene.episode}"
    if log.crashed or log.off_road or log.num_steps < total + 1 or not log.valid[log.ego_id].all():
        what = "crashed" if log.crashed else "left the road"
        raise InputError(f"{where}: the human {what} at {run.time_s:.1f} s, before t0 + horizon = "
                         f"{scene.t0_s + scene.horizon_s:.1f} s; pick another episode or an earlier t0_s")
    step = round(scene.t0_s * control_hz)
    agent_ids = window_rows(log, step, radius_m, max_agents)
    if len(agent_ids) < 2:
        raise InputError(f"{where}: no other vehicle within {radius_m} m of the ego at t0 = "
                         f"{scene.t0_s} s; nothing to attack with, skip this scene")
    built = run.recorder.scene(step, HISTORY_S, scene.horizon_s, WINDOW_DT_S, radius_m, max_agents,
                               source=scene.env_id)
    window = window_of(log, agent_ids, step, scene.future_steps, built.lanes, built.route_xy,
                       scene.env_id)
    # The selection above must be the recorder's own (same rows, same order).
    assert np.array_equal(window.states, built.states) and np.array_equal(window.valid, built.valid)
    return SceneRecord(scene, log, window, agent_ids)


def save_record(record: SceneRecord, path: Path) -> None:
    """`path` (.npz) holds the log, the rows and the lanes; `path`.json the AttackScene."""
    path = Path(path)
    lanes = record.window.lanes
    counts = [len(lane.centre) for lane in lanes]
    empty = np.zeros((0, 2))
    arrays = {
        "log_states": record.log.states, "log_valid": record.log.valid, "log_sizes": record.log.sizes,
        "log_kinds": record.log.kinds, "log_ego_id": np.int64(record.log.ego_id),
        "log_dt_s": np.float64(record.log.dt_s), "log_crashed": np.bool_(record.log.crashed),
        "log_off_road": np.bool_(record.log.off_road), "agent_ids": record.agent_ids,
        "point_offsets": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        "lane_centre": np.concatenate([lane.centre for lane in lanes]) if lanes else empty,
        "lane_left": np.concatenate([lane.left for lane in lanes]) if lanes else empty,
        "lane_right": np.concatenate([lane.right for lane in lanes]) if lanes else empty,
        "lane_lines": np.array([[int(lane.left_line), int(lane.right_line)] for lane in lanes],
                               dtype=np.int64).reshape(-1, 2),
        "lane_width_m": np.array([lane.width_m for lane in lanes]),
        "lane_start_s": np.array([lane.start_s for lane in lanes]),
        "route_xy": empty if record.window.route_xy is None else record.window.route_xy,
        "has_route": np.bool_(record.window.route_xy is not None),
    }
    if record.family:
        arrays["family"] = np.array(record.family)
    write_npz(path, arrays)
    write_json(path.with_suffix(".json"), asdict(record.scene))


def load_record(path: Path) -> SceneRecord:
    """The SceneRecord `save_record` wrote to `path` (bit-identical arrays)."""
    import zipfile

    path = Path(path)
    try:
        scene = AttackScene(**json.loads(path.with_suffix(".json").read_text()))
        with np.load(path) as data:
            d = {key: data[key] for key in data.files}
        missing = sorted({"log_states", "log_valid", "log_sizes", "log_kinds", "log_ego_id", "log_dt_s",
                          "agent_ids", "point_offsets", "lane_centre", "route_xy"} - set(d))
        if missing:
            raise KeyError(f"no {', '.join(missing)}")
    except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as err:
        reason = (str(err).splitlines() or [type(err).__name__])[0] or type(err).__name__
        raise InputError(f"scene record {path} is unreadable ({reason}); record the scenes again "
                         "with `adversary scenes` into a new --out") from None
    floats = [d[k] for k in ("log_sizes", "lane_centre", "route_xy", "log_dt_s")]
    if ((d["log_valid"] & ~np.isfinite(d["log_states"]).all(axis=-1)).any()
            or not all(np.isfinite(a).all() for a in floats)):
        raise InputError(f"scene record {path} holds NaN/inf; record the scenes again with "
                         "`adversary scenes` into a new --out")
    log = HumanLog(d["log_states"], d["log_valid"], d["log_sizes"], d["log_kinds"], int(d["log_ego_id"]),
                   float(d["log_dt_s"]), bool(d["log_crashed"]), bool(d["log_off_road"]))
    offsets = d["point_offsets"]
    lanes = tuple(
        Lane(d["lane_centre"][a:b], d["lane_left"][a:b], d["lane_right"][a:b], LineType(int(lines[0])),
             LineType(int(lines[1])), float(width), float(start))
        for a, b, lines, width, start in zip(offsets[:-1], offsets[1:], d["lane_lines"],
                                             d["lane_width_m"], d["lane_start_s"]))
    route = d["route_xy"] if bool(d["has_route"]) else None
    step = round(scene.t0_s / log.dt_s)
    window = window_of(log, d["agent_ids"], step, scene.future_steps, lanes, route, scene.env_id)
    if scene.recording and not Path(scene.recording).is_file():
        raise InputError(f"scene record {path} was cut from {scene.recording}, which is not there; "
                         "put the recording back or record the scenes again with `adversary scenes`")
    family = str(d["family"]) if "family" in d else ""
    return SceneRecord(scene, log, window, d["agent_ids"].astype(np.int64), family)
