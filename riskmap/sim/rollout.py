"""The rollout: one closed-loop episode with any planner driving the ego.

The world is an `Episode` (highway-env traffic, or `LogReplayEpisode` replaying a record); for
a planner the ego is handed over at t = 0 to a vehicle that a tracking controller drives at
`control_hz`, replanning at `replan_hz` from the recorded 2 s history.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rasterize.config import family_of_env
from rasterize.errors import InputError
from rasterize.frames import box_corners, ego_pose
from rasterize.geometry import box_gap
from riskmap.sim.control import ControllerConfig, TrackingController, hand_over_to_planner
from riskmap.sim.episode import FAMILY_SETUPS, Episode
from riskmap.sim.plan import HumanDriver, check_plan


@dataclass(frozen=True)
class DriveConfig:
    env_id: str
    episodes: int
    seed: int = 0
    control_hz: int = 10
    replan_hz: int = 2
    episode_s: float | None = None     # default: the family's episode length
    gap_radius_m: float = 40.0         # others farther than this do not count for the min gap
    history_s: float = 2.0

    def __post_init__(self) -> None:
        family = family_of_env(self.env_id)
        if self.episode_s is None:
            object.__setattr__(self, "episode_s", FAMILY_SETUPS[family].episode_s)
        if self.control_hz % self.replan_hz:
            raise InputError("control_hz must be a multiple of replan_hz")


def _min_gap(road, ego, radius: float) -> float:
    me = box_corners(ego.position, [np.cos(ego.heading), np.sin(ego.heading)], ego.LENGTH,
                     ego.WIDTH)
    gaps = [box_gap(me, box_corners(v.position, [np.cos(v.heading), np.sin(v.heading)], v.LENGTH,
                                    v.WIDTH))
            for v in road.vehicles
            if v is not ego and np.linalg.norm(v.position - ego.position) < radius]
    return min(gaps, default=float("inf"))


@dataclass(frozen=True)
class DriveHooks:
    """Optional callbacks into one closed-loop episode; the defaults drive it unchanged.

    setup(base_env): rearrange the road before the first record (initial conditions).
    on_reset(run): once the `Episode` is reset, before the ego is handed to the planner.
    on_ready: callables run with the `Episode` once the ego is set up (after the planner's own
        `attach(run)`, if it has one), e.g. to script other traffic.
    perceive(scene, step) -> scene: what the planner is shown instead of the recorded scene
        (perception degradation); frames still show the recorded scene.
    on_plan(run, scene, plan, step): after every replan, with the scene the plan was made from
        (figures: `riskmap.figures.panels.plan_frame_writer`).
    on_step(run): after every control step (measurements, trajectory logging).
    """

    setup: Callable | None = None
    on_reset: Callable | None = None
    on_ready: tuple = ()
    perceive: Callable | None = None
    on_plan: Callable | None = None
    on_step: Callable | None = None


def drive_episode(env, planner, config: DriveConfig, episode: int, hooks: DriveHooks = DriveHooks(),
                  run: Episode | None = None) -> dict:
    """Drive one closed-loop episode; `hooks` perturb or observe it (see `DriveHooks`). `run`: an
    already reset Episode to drive instead of a fresh one (for instance one whose traffic replays
    a log; `hooks.setup` is then not used); the caller can read its recorder afterwards."""
    if run is None:
        run = Episode(env, config.env_id, config.seed, episode, config.control_hz,
                      setup=hooks.setup)
    if hooks.on_reset is not None:
        hooks.on_reset(run)
    human = isinstance(planner, HumanDriver)
    controller = TrackingController(ControllerConfig())
    plan_times, gaps, speeds = [], [], []
    since_plan = 0.0
    replan_every = config.control_hz // config.replan_hz
    if not human:
        vehicle = hand_over_to_planner(run)
        planner.reset(run.recorder.scene(0, config.history_s, 0.0))
    if hasattr(planner, "attach"):
        planner.attach(run)
    for hook in hooks.on_ready:
        hook(run)
    distance = 0.0
    n_steps = int(round(config.episode_s * config.control_hz))
    for k in range(n_steps):
        ego = run.ego
        if not human:
            if k % replan_every == 0:
                scene = run.recorder.scene(run.recorder.num_steps - 1, config.history_s, 0.0,
                                           source=config.env_id)
                seen = scene if hooks.perceive is None else hooks.perceive(scene, k)
                started = time.perf_counter()
                plan = check_plan(planner.plan(seen), type(planner).__name__)
                plan_times.append(time.perf_counter() - started)
                origin, heading = ego_pose(scene)
                controller.set_plan(plan.waypoints, origin, heading)
                since_plan = 0.0
                if hooks.on_plan is not None:
                    hooks.on_plan(run, scene, plan, k)
            state = run.recorder.latest_state(run.recorder.ego_id)
            accel, steer = controller.action(state[:2], float(np.arctan2(state[3], state[2])),
                                             float(state[4]), since_plan, run.dt)
            vehicle.command(accel, steer)
            since_plan += run.dt
        before = ego.position.copy()
        run.step()
        distance += float(np.linalg.norm(run.ego.position - before))
        speeds.append(float(run.ego.speed))
        gaps.append(_min_gap(run.base.road, run.ego, config.gap_radius_m))
        if hooks.on_step is not None:
            hooks.on_step(run)
        if run.done:
            break
    return {
        "episode": episode, "env_seed": run.seed, "driver": run.driver,
        "planner": "idm" if human else type(planner).__name__,
        "collided": run.crashed, "off_road": run.off_network,
        "simulated_s": round(run.time_s, 3), "distance_m": distance,
        "mean_speed_mps": float(np.mean(speeds)) if speeds else 0.0,
        "min_gap_m": float(min(gaps)) if gaps else float("inf"),
        "plan_ms_median": 1000 * float(np.median(plan_times)) if plan_times else None,
        "plan_ms_mean": 1000 * float(np.mean(plan_times)) if plan_times else None,
        "plan_ms_p90": 1000 * float(np.percentile(plan_times, 90)) if plan_times else None,
        "plan_calls": len(plan_times),
    }
