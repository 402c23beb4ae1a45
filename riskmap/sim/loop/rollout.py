"""The rollout: one closed-loop episode with any planner driving the ego.

`drive_world` is the one loop, on any `riskmap.sim.loop.world.World`: an `Episode` (highway-env
traffic, or `LogReplayEpisode` replaying a record) or a `CommonRoadWorld` (a CommonRoad
recording). For a planner the ego is handed over at the start to a vehicle that a tracking
controller drives at the control rate, replanning at `replan_hz` from a 2 s history.
`riskmap.sim.worlds.highway_drive.drive_episode` drives an `Episode` and reports the highway-env metrics.

Every plan is checked against the planner contract (`riskmap.sim.loop.plan_checks`): a plan that
cannot be tracked (wrong shape, NaN/inf) stops the episode; an implausible one (km/h, world
coordinates, impossible speeds, swapped axes) is driven as made and counted in
`LoopRecord.implausible`, which goes into the episode record (`implausible_plans` and
`implausible_plan_first`). A plan is tracked at its own step (`Plan.dt_s`, with its `speeds` if it
gives them). A planner with no plan (`NoSolution`) is counted there too (`no_solution_plans`,
`no_solution_first`) and the ego brakes until the next replan.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rasterize.errors import InputError
from rasterize.frames import ego_pose
from rasterize.timebase import HISTORY_S
from riskmap.sim.loop.control import ControllerConfig, TrackingController
from riskmap.sim.loop.plan import NoSolution, check_plan, traits_of
from riskmap.sim.loop.plan_checks import ImplausiblePlans
from riskmap.sim.records.yield_events import YieldEventCounter


def check_replan_hz(replan_hz: int, control_hz: int) -> None:
    """A planner replans every control_hz / replan_hz control steps, a whole number: InputError
    (naming --replan-hz, the option every command gives it by) otherwise."""
    if replan_hz < 1 or control_hz % replan_hz:
        divisors = ", ".join(str(d) for d in range(1, control_hz + 1) if control_hz % d == 0)
        raise InputError(f"--replan-hz {replan_hz}: must divide the {control_hz} Hz control rate "
                         f"({divisors})")


@dataclass(frozen=True)
class DriveHooks:
    """Optional callbacks into one closed-loop episode; the defaults drive it unchanged. `run` is
    the world driven (the `Episode` for `drive_episode`).

    setup(base_env): rearrange the road before the first record (initial conditions; used where
        `drive_episode` makes the `Episode`).
    on_reset(run): once the world is reset, before the ego is handed to the planner.
    on_ready: callables run with the world once the ego is set up (after the planner's own
        `attach(run)`, if it has one), e.g. to script other traffic.
    perceive(scene, step) -> scene: what the planner is shown instead of the recorded scene
        (perception degradation); frames still show the recorded scene.
    on_plan(run, scene, plan, step): after every replan, with the scene the plan was made from
        (figures: `riskmap.figures.panels.plan_frame_writer`); where the ego drives itself, at
        the same times with `plan` None.
    on_step(run): after every control step (measurements, trajectory logging).
    on_end(run, record): once, after the last step, with the loop's `LoopRecord`.
    """

    setup: Callable | None = None
    on_reset: Callable | None = None
    on_ready: tuple = ()
    perceive: Callable | None = None
    on_plan: Callable | None = None
    on_step: Callable | None = None
    on_end: Callable | None = None


@dataclass(frozen=True)
class LoopConfig:
    """How `drive_world` drives: at most `steps` steps, a new plan every `replan_every`."""

    steps: int
    replan_every: int
    history_s: float = HISTORY_S
    gap_radius_m: float = 40.0         # others farther than this do not count for the min gap


@dataclass
class LoopRecord:
    """What `drive_world` measured; per-step lists hold one entry per step driven."""

    drives_itself: bool                # the planner was the world's own ego (no plans)
    distance_m: float
    speeds: list[float]
    gaps: list[float]
    plan_times_s: list[float]
    yield_events: int = 0              # waits while a crossing vehicle passed (`yield_events`)
    implausible: ImplausiblePlans = field(default_factory=ImplausiblePlans)   # driven as made


class _Tracker:
    """Replans every `replan_every` steps and turns the plan into the ego's command each step."""

    def __init__(self, world, planner, vehicle, config: LoopConfig, hooks: DriveHooks):
        self.world, self.planner, self.vehicle = world, planner, vehicle
        self.config, self.hooks = config, hooks
        self.controller = TrackingController(ControllerConfig())
        self.since_plan = 0.0
        self.plan_times: list[float] = []
        self.implausible = ImplausiblePlans()

    def _replan(self, k: int) -> None:
        world, hooks = self.world, self.hooks
        scene = world.scene(self.config.history_s)
        seen = scene if hooks.perceive is None else hooks.perceive(scene, k)
        started = time.perf_counter()
        try:
            made = self.planner.plan(seen)
        except NoSolution as why:
            # Counted, never hidden: the ego brakes until a later replan finds a plan.
            self.plan_times.append(time.perf_counter() - started)
            self.implausible.add_no_solution(1, f"at {seen.time_s:.1f} s: {why or 'no trajectory'}")
            self.controller.brake()
            self.since_plan = 0.0
            if hooks.on_plan is not None:
                hooks.on_plan(world, scene, None, k)
            return
        plan = check_plan(made, type(self.planner).__name__)
        self.plan_times.append(time.perf_counter() - started)
        # Counted, not replaced: tracking it as before keeps every good planner's drive unchanged,
        # and the count tells that a run's numbers came from plans that break the contract.
        self.implausible.check(plan, seen)
        # The plan is pinned to where the ego really is, not where a degraded scene shows it.
        origin, heading = ego_pose(scene)
        if plan.timed:
            self.controller.set_plan(plan.waypoints, origin, heading, plan.dt_s, plan.speeds)
        else:
            self.controller.set_plan(plan.waypoints, origin, heading)
        self.since_plan = 0.0
        if hooks.on_plan is not None:
            hooks.on_plan(world, scene, plan, k)

    def command(self, k: int) -> None:
        if k % self.config.replan_every == 0:
            self._replan(k)
        dt = self.world.dt
        state = self.world.ego_state()
        accel, steer = self.controller.action(state[:2], float(np.arctan2(state[3], state[2])),
                                              float(state[4]), self.since_plan, dt)
        self.vehicle.command(accel, steer)
        self.since_plan += dt


def drive_world(world, planner, config: LoopConfig, hooks: DriveHooks = DriveHooks()) -> LoopRecord:
    """The closed loop on any `riskmap.sim.loop.world.World`: hand the ego to `planner` (unless it
    drives itself), then step until `config.steps` or the world is done (`hooks`: `DriveHooks`,
    whose `setup` belongs to the world's construction and is not used here)."""
    if hooks.on_reset is not None:
        hooks.on_reset(world)
    traits = traits_of(planner)
    human = bool(traits.drives_itself)
    tracker = None
    if not human:
        vehicle, first = world.hand_over(config.history_s)
        planner.reset(first)
        tracker = _Tracker(world, planner, vehicle, config, hooks)
    if traits.attach is not None:
        traits.attach(world)
    for hook in hooks.on_ready:
        hook(world)
    distance, speeds, gaps = 0.0, [], []
    yields = YieldEventCounter(world.dt)
    for k in range(config.steps):
        if tracker is not None:
            tracker.command(k)
        elif hooks.on_plan is not None and k % config.replan_every == 0:
            # A self-driving ego makes no plan, but frames of its drive are still wanted.
            hooks.on_plan(world, world.scene(config.history_s), None, k)
        before = world.ego.position.copy()
        world.step()
        distance += float(np.linalg.norm(world.ego.position - before))
        speeds.append(float(world.ego.speed))
        gaps.append(world.min_gap(config.gap_radius_m))
        yields.update(speeds[-1], lambda: world.scene(0.0))
        if hooks.on_step is not None:
            hooks.on_step(world)
        if world.done:
            break
    record = LoopRecord(human, distance, speeds, gaps, [] if tracker is None else tracker.plan_times,
                        yields.finish(), ImplausiblePlans() if tracker is None else tracker.implausible)
    if hooks.on_end is not None:
        hooks.on_end(world, record)
    return record
