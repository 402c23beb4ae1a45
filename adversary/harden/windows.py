"""Training windows from a successful attack: the attacked scene, a collision-free ego through it.

An attack record (`adversary attack`) holds the adversary's generated trajectory and, since the
hardening loop, the attacked ego's 10 Hz drive (`ego_states`; older records are driven again).
From it:

    1. the ego's first collision with the adversary, k_c (the judge's criterion, IoU > 0.02);
    2. a collision-free alternative from k_s = k_c - `lookback_s`: of the judge's solution family
       (`riskmap.sim.records.alternatives`: constant accelerations along the ego's own path, else one
       lane width left or right), clear of every box up to the end of the drive (not only to
       k_c) and on the road, the one that keeps the most room to every other vehicle (`choice`);
    3. failing that, the human's own recorded drive where it collides with nobody (on recorded
       scenes the ego was the human until t0, so its history is the planner's too);
    4. the counterfactual drive: log playback of that ego (the planner's states up to k_s, the
       alternative after) against the spliced log (`judge.rollout` with `ego_states`), checked
       collision-free again on the boxes it drove, and cut into windows as `riskmap collect` cuts
       them (2 s of history, 6 s of future at 2 Hz) every `stride_s` from `before_s` before k_s
       to k_c. The adversary is in every window as the scene's other agents are, so the
       uncertainty map of a window covers it.

Past the end of the attack (t0 + 6 s) the alternative goes on by its own rule, so every window
has its full 6 s of demonstrated future; the other agents' futures there are invalid (a sample
reads only their present and past).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from adversary.crash.attack import replan_hz_of
from adversary.crash.judge import (
    SOLUTION_LATERAL_ACCELS_MPS2,
    WINDOW_FUTURE_S,
    WINDOW_HISTORY_S,
    _first_collision,
    drivable_area,
    first_collision,
    rollout,
    splice_tracks,
)
from adversary.crash.scenes import WINDOW_DT_S, SceneRecord
from rasterize.errors import InputError
from rasterize.tracks import Tracks
from riskmap.sim.loop.plan import traits_of
from riskmap.sim.records.alternatives import (
    alternative_track,
    first_clear_alternative,
    safest_clear_alternative,
)
from riskmap.sim.records.metrics import box_off_road

# Accelerations tried along the path, mildest first.
ACCELS_MPS2 = (0.0, -2.0, 1.0, -4.0, 2.0, -6.0, -8.0)   # ties go to the mildest
DEMONSTRATIONS = ("safest", "defensive", "lateral", "mildest")


@dataclass(frozen=True)
class HardenWindowConfig:
    """How an attack becomes windows. Seconds; accelerations m/s²."""

    lookback_s: float = 3.0           # the alternative starts this long before the collision
    before_s: float = 1.0             # first window this long before the alternative starts
    stride_s: float = 0.5             # between windows
    accels_mps2: tuple[float, ...] = ACCELS_MPS2
    lateral_accels_mps2: tuple[float, ...] = SOLUTION_LATERAL_ACCELS_MPS2
    human_fallback: bool = True       # the human's own drive where no alternative is clear
    # Which clear alternative demonstrates: "safest" keeps the largest smallest gap to every other
    # vehicle up to the end of the attack; "defensive" the same among those that never speed up;
    # "lateral" the safest lane change where one is clear (a route-goal planner can express a
    # path beside the threat, hardly one that stops short of its goal), else the safest;
    # "mildest" departs least from the attacked drive (the first clear in `accels_mps2`' order).
    # experiments/README, "Hardening", has what each did.
    choice: str = "safest"
    # Learn only from failures that say something about the planner: a valid attack the ego could
    # have avoided after seeing it (`riskmap.sim.records.failures`); a record from before the
    # classification is used as it was.
    valid_avoidable_only: bool = True

    def __post_init__(self) -> None:
        if self.choice not in DEMONSTRATIONS:
            raise InputError(f"choice {self.choice!r} must be one of {', '.join(DEMONSTRATIONS)}")
        for name in ("lookback_s", "stride_s"):
            value = getattr(self, name)
            if not value > 0 or abs(value / WINDOW_DT_S - round(value / WINDOW_DT_S)) > 1e-9:
                raise InputError(f"{name}={value} must be a positive multiple of {WINDOW_DT_S} s")
        if not 0 <= self.before_s < 60:
            raise InputError(f"before_s={self.before_s} must be in [0, 60) s")


@dataclass(frozen=True)
class HardenWindows:
    """What one attack gave: its windows (Scenes, possibly none) and how (JSON-ready `info`)."""

    scenes: tuple
    info: dict


def attacked_drive(record: SceneRecord, attack: dict, planner, planner_spec: str) -> tuple[Tracks, list[int]]:
    """(tracks, log agent of each row but the last) of the attacked drive with the ego in the
    last row: the
    spliced log's agents (they replay it exactly) and the ego as the attack record holds it
    (`ego_states`), or as the planner drives it again for records from before they did."""
    tracks, rows = np.asarray(attack["tracks"], dtype=np.float64), attack["metrics"]["spliced_rows"]
    log = splice_tracks(record, tracks, rows)
    if attack.get("ego_states") is not None:
        ego = np.asarray(attack["ego_states"], dtype=np.float64)
    else:
        drove = rollout(record, tracks, rows, planner, planner_spec, replan_hz=replan_hz_of(attack))
        ego = drove.states[drove.ego][drove.valid[drove.ego]]
    # Both drives start from the episode's reset state; the record's rounding must not move it.
    ego[0] = log.states[log.ego_id, 0]
    steps = min(len(ego), log.num_steps)
    others = [a for a in range(len(log.sizes)) if a != log.ego_id]
    states = np.concatenate([log.states[others, :steps], ego[None, :steps]])
    valid = np.concatenate([log.valid[others, :steps], np.ones((1, steps), bool)])
    sizes = np.concatenate([log.sizes[others], log.sizes[log.ego_id:log.ego_id + 1]])
    kinds = np.concatenate([log.kinds[others], log.kinds[log.ego_id:log.ego_id + 1]])
    return Tracks(states, valid, sizes, kinds), others


def _lane_width_m(lanes) -> float:
    return float(np.median([lane.width_m for lane in lanes])) if lanes else 4.0


def clear_alternative(tracks: Tracks, ego: int, adversary: int, dt_s: float, lanes,
                      config: HardenWindowConfig, from_step: int = 0) -> tuple[np.ndarray | None, dict]:
    """Steps 1 and 2 of the module docstring on a drive's `tracks` (agent `ego` collided with
    agent `adversary` at or after `from_step`; `lanes` the road's): the collision-free ego
    [S + future, 6] from the drive's steps 0 ... S - 1 on, and
    how it was found, or (None, why); info["collision_step"] is absent only if they never touch."""
    k_c, _, _ = first_collision(tracks, ego, [adversary], from_step)
    if k_c is None:
        return None, {"why": "the attacked drive no longer collides with the adversary"}
    end = tracks.num_steps - 1
    start = max(1, k_c - round(config.lookback_s / dt_s))
    extra = round(WINDOW_FUTURE_S / dt_s)
    area = drivable_area(lanes)

    def on_road(centre, heading, length, width):
        return not box_off_road(np.array([*centre, *heading]), (length, width), area)

    lane = _lane_width_m(lanes)
    if config.choice in ("safest", "defensive", "lateral"):     # whichever keeps most room
        keep = (lambda a: a <= 0.0) if config.choice == "defensive" else (lambda a: True)
        along = tuple(a for a in config.accels_mps2 if keep(a))
        sideways = tuple(a for a in config.lateral_accels_mps2 if keep(a))

        def along_path():
            return safest_clear_alternative(tracks, ego, start, end, dt_s, along)

        def to_the_side():
            return safest_clear_alternative(tracks, ego, start, end, dt_s, sideways, (lane, -lane),
                                            on_road=on_road)

        found = (to_the_side() or along_path()) if config.choice == "lateral" else (along_path() or to_the_side())
    else:
        found = first_clear_alternative(tracks, ego, start, end, dt_s, config.accels_mps2) or \
            first_clear_alternative(tracks, ego, start, end, dt_s, config.lateral_accels_mps2,
                                    (lane, -lane), on_road=on_road)
    info = {"collision_step": int(k_c), "start_step": int(start), "end_step": int(end)}
    if found is None:
        return None, {**info, "why": "no alternative is clear"}
    accel, offset = found
    after = alternative_track(tracks.states, tracks.valid, ego, start, end - start + extra, dt_s, accel,
                              offset, path_until=end)
    full = np.concatenate([tracks.states[ego, :start + 1], after])
    return full, {**info, "demonstration": "alternative", "accel_mps2": accel, "offset_m": offset}


def counterfactual_ego(record: SceneRecord, attack: dict, planner, planner_spec: str,
                       config: HardenWindowConfig) -> tuple[np.ndarray | None, dict]:
    """The collision-free ego [S + future, 6] (the log's steps from 0, then `WINDOW_FUTURE_S` more)
    and how it was found, or (None, why)."""
    tracks, others = attacked_drive(record, attack, planner, planner_spec)
    ego = len(others)
    adversary = others.index(int(record.agent_ids[attack["adversary_row"]]))
    dt = record.log.dt_s
    full, info = clear_alternative(tracks, ego, adversary, dt, record.window.lanes, config,
                                   from_step=record.t0_step)
    if full is not None or "collision_step" not in info or not config.human_fallback:
        return full, info
    info = {k: v for k, v in info.items() if k != "why"}
    end, extra = info["end_step"], round(WINDOW_FUTURE_S / dt)
    human = splice_tracks(record, np.asarray(attack["tracks"]), attack["metrics"]["spliced_rows"])
    mine = human.states[human.ego_id, :end + 1]
    if not human.valid[human.ego_id, :end + 1].all():
        return None, {**info, "why": "no alternative is clear and the human left the log"}
    return np.concatenate([mine, constant_velocity(mine[-1], extra, dt)]), \
        {**info, "demonstration": "human", "start_step": 0}


def constant_velocity(state: np.ndarray, steps: int, dt_s: float) -> np.ndarray:
    """States [steps, 6] going on from `state` at its speed and heading (no turning)."""
    times = dt_s * np.arange(1, steps + 1)
    out = np.tile(state, (steps, 1))
    out[:, :2] = state[:2] + (state[4] * times)[:, None] * state[2:4]
    out[:, 5] = 0.0
    return out


NO_HISTORY = f"the collision comes before a window's {WINDOW_HISTORY_S:g} s of history"


def window_steps(info: dict, config: HardenWindowConfig, dt_s: float, last_step: int) -> tuple[int, ...]:
    """The 10 Hz steps windows are cut at: every `stride_s` from `before_s` before the alternative
    starts (never before the window's history fits) to the collision step."""
    stride = round(config.stride_s / dt_s)
    first = max(round(WINDOW_HISTORY_S / dt_s), info["start_step"] - round(config.before_s / dt_s))
    last = min(info["collision_step"], last_step)
    return tuple(range(first, last + 1, stride))


def with_demonstrated_future(scene, ego_full: np.ndarray, step: int, dt_s: float):
    """`scene` (cut at log step `step`) with the ego's future from `ego_full` wherever the drive
    had ended (the alternative's own continuation)."""
    stride = round(scene.dt / dt_s)
    states, valid = scene.states.copy(), scene.valid.copy()
    ego, now = scene.ego_index, scene.current_index
    for j in range(1, states.shape[1] - now):
        k = step + j * stride
        if not valid[ego, now + j] and k < len(ego_full):
            states[ego, now + j], valid[ego, now + j] = ego_full[k], True
    return replace(scene, states=states, valid=valid)


def hardening_windows(record: SceneRecord, attack: dict, planner, planner_spec: str,
                      config: HardenWindowConfig = HardenWindowConfig()) -> HardenWindows:
    """The training windows of one attack record (module docstring); none for a record without a
    collision, without a clear alternative, or whose counterfactual drive still collides."""
    from riskmap.sim.worlds.log_replay import ReplayPlanner

    name = attack.get("name", record.scene.where)
    if attack.get("status") != "ok" or not attack.get("collision"):
        return HardenWindows((), {"scene": name, "windows": 0, "why": "no collision"})
    if attack["metrics"].get("collision_before_t0"):
        return HardenWindows((), {"scene": name, "windows": 0, "why": "the ego collided before t0"})
    failure = attack["metrics"].get("failure")
    if config.valid_avoidable_only and failure and not (failure.get("valid_attack") and failure["avoidable"]):
        why = "not a valid attack" if not failure.get("valid_attack") else "unavoidable for a driver who must see it first"
        return HardenWindows((), {"scene": name, "windows": 0, "why": why})
    ego_full, info = counterfactual_ego(record, attack, planner, planner_spec, config)
    info = {"scene": name, **info}
    if ego_full is None:
        return HardenWindows((), {**info, "windows": 0})
    steps = window_steps(info, config, record.log.dt_s, record.log.num_steps - 1)
    if not steps:
        return HardenWindows((), {**info, "windows": 0, "why": NO_HISTORY})
    replay = ReplayPlanner()
    # Recorded scenes route the windows as the planner under attack is routed (its training rule).
    replay.route_settings = traits_of(planner).route_settings
    tracks, rows = np.asarray(attack["tracks"]), attack["metrics"]["spliced_rows"]
    drove = rollout(record, tracks, rows, replay, "replay", ego_states=ego_full[:record.log.num_steps],
                    scene_steps=steps)
    everyone = [a for a in range(len(drove.sizes)) if a != drove.ego]
    hit, _, _ = _first_collision(drove, drove.ego, everyone, 0)
    if hit is not None:
        return HardenWindows((), {**info, "windows": 0, "why": f"the counterfactual drive collides at step {hit}"})
    scenes = tuple(with_demonstrated_future(scene, ego_full, k, record.log.dt_s)
                   for scene, k in zip(drove.scenes, steps))
    return HardenWindows(scenes, {**info, "windows": len(scenes), "steps": list(steps)})
