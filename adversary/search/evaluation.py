"""One closed-loop evaluation of one scenario: drive it with a planner, score it.

The ego is driven by any planner SPEC through `riskmap.sim.worlds.highway_drive.drive_episode`; the template's
`Scenario` supplies the initial conditions and the perception degradation through `DriveHooks`.
Planners and environments are built once per process (evaluations run in worker processes).
Perception parameters act on planners through the `Scene` they are shown, and on the `idm` ego
through the ghost vehicles it decides on (`adversary.search.perceived_idm`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from adversary.search.objectives import (
    ObjectiveScales,
    journey_distance_m,
    penalised_objectives,
    required_gap_m,
    scene_alteration,
    total_distance_m,
)
from adversary.search.scenarios import ENV_ID, Scenario, Template
from rasterize.frames import world_from_highway_env
from rasterize.timebase import CONTROL_HZ

MAX_SPEED_MPS = 40.0                 # highway-env's vehicle speed cap


@dataclass(frozen=True)
class EvaluationConfig:
    planner: str                     # planner SPEC (riskmap.registry)
    template: str
    seed: int = 0                    # planner sampling and perception noise
    episode_s: float = 10.0          # simulated seconds per evaluation
    control_hz: int = CONTROL_HZ

    @property
    def steps(self) -> int:
        return round(self.episode_s * self.control_hz)


_PROCESS_CACHE: dict = {}


def _planner_and_env(config: EvaluationConfig):
    """This process's planner and env for `config` (built on first use)."""
    from riskmap.registry import make_planner
    from riskmap.sim.worlds.episode import make_env

    key = (config.planner, config.seed, config.control_hz)
    if key not in _PROCESS_CACHE:
        # One entry: a campaign worker runs searches with many seeds one after another.
        _PROCESS_CACHE.clear()
        env = make_env(ENV_ID, config.control_hz)
        env.unwrapped.config["vehicles_count"] = 0     # templates place their own vehicles
        _PROCESS_CACHE[key] = (make_planner(config.planner, seed=config.seed), env)
    return _PROCESS_CACHE[key]


def constraint_value(template: Template, values: np.ndarray) -> float:
    """G ≤ 0 feasible: the required braking gap minus the initial gap (objectives module)."""
    p = template.as_dict(values)
    b = template.base
    speed, final = template.target_speeds(p)
    return required_gap_m(b.ego_speed_mps, b.ego_brake_mps2, speed, final, p["brake_mps2"]) - p["gap_m"]


def objective_scales(template: Template, config: EvaluationConfig) -> ObjectiveScales:
    return ObjectiveScales(journey_max_m=MAX_SPEED_MPS * config.episode_s, steps_max=config.steps,
                           n_params=len(template.parameters))


@dataclass
class Trajectory:
    """World positions [T, 2] of the ego and the target after every control step (T ≤ steps),
    with the initial positions first."""

    ego_xy: list
    target_xy: list
    failure: dict | None = None       # the collision's class (riskmap.sim.records.failures), None without one

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.ego_xy), np.asarray(self.target_xy)


def run_scenario(template: Template, values: np.ndarray, config: EvaluationConfig,
                 frames_dir: Path | None = None, on_step=None, on_reset=None,
                 wrap_planner=None, on_ready: tuple = ()) -> tuple[dict, Trajectory]:
    """Drive one scenario; returns the drive record and the trajectories of ego and target.
    on_reset, on_step, on_ready: extra `DriveHooks` callbacks; wrap_planner(planner) -> the
    planner that drives (e.g. one that keeps its last plan)."""
    from riskmap.sim.loop.rollout import DriveHooks
    from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

    planner, env = _planner_and_env(config)
    if wrap_planner is not None:
        planner = wrap_planner(planner)
    scenario = Scenario(template, template.as_dict(values), config.seed, 1.0 / config.control_hz)
    trajectory = Trajectory([], [])

    driven = {}

    def log(run):
        driven["run"] = run
        if not trajectory.ego_xy:
            trajectory.ego_xy.append(world_from_highway_env(start_ego))
            trajectory.target_xy.append(world_from_highway_env(start_target))
        trajectory.ego_xy.append(world_from_highway_env(run.ego.position.copy()))
        trajectory.target_xy.append(world_from_highway_env(scenario.target.position.copy()))
        if on_step is not None:
            on_step(run)

    def setup(base_env):
        nonlocal start_ego, start_target
        scenario.setup(base_env)
        start_ego = base_env.vehicle.position.copy()
        start_target = scenario.target.position.copy()

    start_ego = start_target = None
    drive_config = DriveConfig(ENV_ID, episodes=1, seed=config.seed, control_hz=config.control_hz,
                               episode_s=config.episode_s)
    frames = None
    if frames_dir is not None:
        from riskmap.figures.panels import plan_frame_writer

        frames = plan_frame_writer(frames_dir, planner, "episode_000000", f"{ENV_ID} episode 0", ENV_ID)
    hooks = DriveHooks(setup=setup, on_reset=on_reset, on_ready=tuple(on_ready), perceive=scenario.perceive,
                       on_plan=frames, on_step=log)
    record = drive_episode(env, planner, drive_config, 0, hooks)
    if record["collided"] and "run" in driven:
        from riskmap.sim.records.failures import classify_run

        trajectory.failure = classify_run(driven["run"], scenario.target)
    return record, trajectory


def evaluate(template: Template, values: np.ndarray, config: EvaluationConfig) -> dict:
    """The stored record of one evaluation: parameters, outcome, raw and penalised objectives.

    Infeasible vectors (G > 0) are not driven: the scene is not solvable in principle.
    """
    values = np.asarray(values, dtype=np.float64)
    g = constraint_value(template, values)
    alteration = scene_alteration(values, template.neutral, template.lower, template.upper)
    record = {"params": template.as_dict(values), "x": values.tolist(), "G": g,
              "feasible": bool(g <= 0), "alteration": alteration}
    if g > 0:
        # pymoo ranks infeasible solutions by G alone; F is a placeholder that dominates nothing.
        return record | {"collided": False, "F": [1.0, 1.0, 1.0]}
    drive, trajectory = run_scenario(template, values, config)
    ego_xy, target_xy = trajectory.arrays()
    journey = journey_distance_m(ego_xy)
    total = total_distance_m(ego_xy, target_xy)
    collided = bool(drive["collided"])
    f = penalised_objectives(journey, total, alteration, collided, objective_scales(template, config))
    return record | {
        "collided": collided, "failure": trajectory.failure, "off_road": bool(drive["off_road"]),
        "simulated_s": drive["simulated_s"], "journey_m": journey, "total_distance_m": total,
        "min_gap_m": drive["min_gap_m"], "F": f.tolist(),
    }
