"""Training windows from the black-box search's failures (`adversary search`), as from CRASH's.

A search evaluation that collided names a template and a parameter vector; its scripted target
does not react to the ego (`adversary.search.scenarios.TargetScript`), so the scenario is a log
the ego can be driven through again. For each one:

    1. the scenario is driven again with the search's own settings (planner, seed, template:
       the same drive), contact switched off as the CRASH judge does, so the drive goes on to its
       end and the boxes are measured (IoU > 0.02, the judge's criterion);
    2. the collision-free alternative is found on that drive as for an attack
       (`adversary.harden.windows.clear_alternative`: the judge's solution family, `choice`);
    3. the scenario is driven a third time with the ego following the alternative (`replay`
       log playback, the search's perception left as it was: the planner is not asked), checked
       collision-free on the boxes it drove, and cut into windows every `stride_s` from
       `before_s` before the alternative starts to the collision step, as attack windows are.

The windows show the road as it was (the recorder's scene), not as a degraded sensor reported
it: the demonstration is what a driver who saw the target would have done.
"""

from __future__ import annotations

import numpy as np

from adversary.crash.highway_source import _no_contact_response
from adversary.crash.judge import WINDOW_FUTURE_S, WINDOW_HISTORY_S, first_collision
from adversary.crash.scenes import CONTROL_HZ, WINDOW_DT_S
from adversary.harden.windows import (
    NO_HISTORY,
    HardenWindowConfig,
    HardenWindows,
    clear_alternative,
    window_steps,
    with_demonstrated_future,
)
from rasterize.tracks import Tracks
from riskmap.sim.worlds.log_replay import HumanLog, ReplayPlanner


def _drive(search_config: dict, values: np.ndarray, wrap_planner=None):
    """(drive record, the recorder) of one scenario of a search with settings `search_config`."""
    from adversary.search.evaluation import EvaluationConfig, run_scenario
    from adversary.search.scenarios import get_template

    kept = {}
    evaluation = EvaluationConfig(search_config["planner"], search_config["template"], search_config["seed"],
                                  search_config["episode_s"], CONTROL_HZ)
    drive, _ = run_scenario(get_template(search_config["template"]), values, evaluation,
                            on_reset=lambda run: kept.setdefault("run", run), wrap_planner=wrap_planner,
                            on_ready=(_no_contact_response,))
    return drive, kept["run"].recorder


def _following(ego_states: np.ndarray, size: np.ndarray, dt_s: float) -> ReplayPlanner:
    """Log playback of the ego states [S, 6] (10 Hz from the scenario's start)."""
    replay = ReplayPlanner()
    replay.set_log(HumanLog(ego_states[None], np.ones((1, len(ego_states)), bool), size[None],
                            np.zeros(1, np.int64), 0, dt_s, False, False))
    return replay


def _others(tracks: Tracks, ego: int) -> list[int]:
    return [a for a in range(tracks.num_agents) if a != ego]


def search_failure_windows(search_config: dict, values: np.ndarray,
                           config: HardenWindowConfig | None = None) -> HardenWindows:
    """The training windows of one search evaluation (module docstring): `search_config` is the
    search's run.json "config", `values` the evaluation's parameter vector ("x"); `config` by
    default `HardenWindowConfig()`."""
    from adversary.search.scenarios import ENV_ID

    config = config or HardenWindowConfig()
    values = np.asarray(values, dtype=np.float64)
    _, recorder = _drive(search_config, values)
    tracks = recorder.tracks()
    ego, sizes = recorder.ego_id, tracks.sizes
    dt = recorder.dt_s
    lanes = recorder.scene(recorder.num_steps - 1, 0.0, 0.0, source=ENV_ID).lanes
    hit, target, _ = first_collision(tracks, ego, _others(tracks, ego), 0)
    if hit is None:
        return HardenWindows((), {"windows": 0, "why": "the search's drive does not collide"})
    ego_full, info = clear_alternative(tracks, ego, target, dt, lanes, config)
    if ego_full is None:
        return HardenWindows((), {**info, "windows": 0})
    steps = window_steps(info, config, dt, recorder.num_steps - 1)
    if not steps:
        return HardenWindows((), {**info, "windows": 0, "why": NO_HISTORY})
    _, again = _drive(search_config, values, wrap_planner=lambda _: _following(ego_full, sizes[ego], dt))
    drove = again.tracks()
    hit, _, _ = first_collision(drove, again.ego_id, _others(drove, again.ego_id), 0)
    if hit is not None:
        return HardenWindows((), {**info, "windows": 0, "why": f"the alternative's drive collides at step {hit}"})
    scenes = tuple(with_demonstrated_future(again.scene(k, WINDOW_HISTORY_S, WINDOW_FUTURE_S, WINDOW_DT_S,
                                                        source=ENV_ID), ego_full, k, dt) for k in steps)
    return HardenWindows(scenes, {**info, "windows": len(scenes), "steps": list(steps)})

