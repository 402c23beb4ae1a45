"""The planner contract: the `Plan` a planner returns, the `Planner` protocol, and its checks.

Every planner that can drive the ego implements `reset(scene)` and `plan(scene) -> Plan`; the
rollout (`riskmap.sim.loop.rollout`) replans at 2 Hz and tracks the waypoints with a controller.
`HumanDriver` marks the IDM/MOBIL ego, which drives itself (`drives_itself`) and makes no plan.

A plan has two forms: the classic one, 12 waypoints 0.5 s apart (`Plan.dt_s` at its default,
no `speeds`), which every learnt planner makes, and the timed one, any K >= 1 waypoints at any
step `dt_s` >= MIN_PLAN_DT_S, optionally with the speed (m/s) at each waypoint, which a
planner following another framework's trajectory type makes (a CommonRoad `Trajectory` at
0.1 s, `riskmap.planner.commonroad_planner`). The controller tracks either at its own step.
A planner with no plan now raises `NoSolution`: the loop counts it and brakes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Protocol, runtime_checkable

import numpy as np

from rasterize.errors import InputError
from rasterize.scene import Scene
from rasterize.timebase import PLAN_DT_S, PLAN_STEPS  # noqa: F401  (re-exported: 12 waypoints, 0.5 s apart)


# The shortest step between waypoints a plan may have (s): the control period (10 Hz), below
# which the controller could not tell two waypoints apart in time.
MIN_PLAN_DT_S = 0.1


class NoSolution(Exception):
    """Raised by `plan(scene)` when the planner has no plan for this scene (a search that found
    no trajectory). The loop counts it (`ImplausiblePlans.no_solution`, the records'
    `no_solution_plans`) and brakes to a stop until the next replan; it never hides it."""


@dataclass
class Plan:
    """waypoints [12, 2]: ego frame (x forward, y left), metres, at 0.5 s steps over 6 s.

    Timed form (module docstring): waypoints [K, 2] at `dt_s` steps (s, >= MIN_PLAN_DT_S), where
    the ego should be dt_s, 2 dt_s, ..., K dt_s from now; `speeds` [K] (m/s) the speed there, or
    None to take the speeds the waypoints' spacing implies. The classic form is dt_s = 0.5 with
    no speeds, and must then be exactly [12, 2].

    The intermediate products are there for figures; planners without them leave them None.
    risk_map, goal_map, svf [G, G]; policy [5, G, G]; timings_s: seconds per stage.
    A space-time planner (DESIGN §3b) also gives risk_steps [T, G, G] (r_t; risk_map is r_1,
    the map in force now) and svf_steps [T, G, G] (D_t; svf is their sum).

    `svf` (and `svf_steps`) may be given as a function of no arguments: it is then computed
    when first read, its seconds added to timings_s["svf"] (not to "total", the time to the
    waypoints). Only figures and open-loop metrics read it, so a closed-loop replan does not pay
    for it.
    """

    waypoints: np.ndarray
    risk_map: np.ndarray | None = None
    goal_map: np.ndarray | None = None
    policy: np.ndarray | None = None
    svf: np.ndarray | Callable[[], np.ndarray] | None = None
    goal_cell: tuple[int, int] | None = None
    timings_s: dict = field(default_factory=dict)
    risk_steps: np.ndarray | None = None
    svf_steps: np.ndarray | Callable[[], np.ndarray] | None = None
    dt_s: float = PLAN_DT_S
    speeds: np.ndarray | None = None

    @property
    def timed(self) -> bool:
        """Whether the plan uses the timed form (its own step, or speeds)."""
        return self.dt_s != PLAN_DT_S or self.speeds is not None

    def __getstate__(self) -> dict:
        """A pickled plan (sent to another process) carries its computed SVFs, not functions."""
        return {**self.__dict__, "_svf": self.svf, "_svf_steps": self.svf_steps}


def _lazy(name: str, doc: str) -> property:
    """A Plan attribute that may be set to a function of no arguments, called when first read."""
    slot = "_" + name

    def read(plan: Plan):
        value = plan.__dict__.get(slot)
        if callable(value):
            start = time.perf_counter()
            value = plan.__dict__[slot] = value()
            plan.timings_s["svf"] = plan.timings_s.get("svf", 0.0) + time.perf_counter() - start
        return value

    def write(plan: Plan, value) -> None:
        plan.__dict__[slot] = value

    return property(read, write, doc=doc)


Plan.svf = _lazy("svf", "expected visits [G, G] (computed when first read)")
Plan.svf_steps = _lazy("svf_steps", "visitation per step [T, G, G], space-time planners only")


@runtime_checkable
class Planner(Protocol):
    """What drives the ego: `reset` once per episode, `plan` at every replan (2 Hz).

    A planner may also declare the optional attributes of `PlannerTraits` (`drives_itself`,
    `requires_log`, `attach`, ...); whatever it leaves out takes the default listed there. They
    are not members of this protocol, so that `isinstance(x, Planner)` still asks for the two
    methods alone, and nothing reads them except through `traits_of`.
    """

    def reset(self, scene: Scene) -> None: ...

    def plan(self, scene: Scene) -> Plan: ...


def _declared(default, meaning: str, read_by: str):
    """A `PlannerTraits` field: its default, what declaring it means and which code reads it."""
    return field(default=default, metadata={"meaning": meaning, "read_by": read_by})


@dataclass(frozen=True)
class PlannerTraits:
    """Every optional declaration a planner may make, as an attribute of the same name, with the
    default a planner that does not declare it gets. The one list: `traits_of` reads a planner
    by it, and the table of declarations in docs/guide/your-own-planner.md is made from it
    (`declarations_table`)."""

    drives_itself: bool = _declared(
        False, "the world's own IDM/MOBIL ego keeps driving; `plan` is never called",
        "riskmap.sim.loop.rollout, riskmap.registry, riskmap.guard.guarded, check-planner")
    requires_log: bool = _declared(
        False, "needs the recorded episode: `set_log(log)` is called before it drives",
        "riskmap.evaluation.evaluate")
    set_log: Callable | None = _declared(
        None, "`set_log(log)`: takes the recorded episode (with `requires_log`)",
        "riskmap.evaluation.evaluate")
    attach: Callable | None = _declared(
        None, "`attach(world)`: called once the ego is set up, before the first step",
        "riskmap.sim.loop.rollout")
    name: str = _declared(
        "idm", "the name records give a planner that drives itself (others: their class name)",
        "riskmap.sim.loop.rollout")
    raster: object | None = _declared(
        None, "its `RasterConfig`: plan figures are drawn on it (else the family's extent)",
        "riskmap.figures.panels, riskmap.guard.guarded")
    route_settings: dict | None = _declared(
        None, "the route rule of its recorded training data, used on CommonRoad recordings",
        "riskmap.sim.worlds.commonroad_replay, adversary.harden.windows")
    guard: object | None = _declared(
        None, "its `riskmap.guard.guarded.Guard`: attack records report the guard's counts",
        "adversary.attacks.episode")


def traits_of(planner) -> PlannerTraits:
    """What `planner` declares, each attribute it lacks at its `PlannerTraits` default (None for
    no planner). Read by attribute, never by class, so that a wrapper forwarding attributes
    declares what the planner inside it does."""
    declared = {f.name: getattr(planner, f.name) for f in fields(PlannerTraits)
                if planner is not None and hasattr(planner, f.name)}
    return PlannerTraits(**declared)


def declarations_table() -> str:
    """The Markdown table of the optional declarations (docs/guide/your-own-planner.md, "The planner
    contract"), one row per `PlannerTraits` field."""
    rows = ["| declaration | default | meaning |", "| --- | --- | --- |"]
    for f in fields(PlannerTraits):
        rows.append(f"| `{f.name}` | `{f.default!r}` | {f.metadata['meaning']} |")
    return "\n".join(rows)


def drives_itself(planner) -> bool:
    """Whether `planner` declares that the world's own IDM/MOBIL ego keeps driving (`HumanDriver`)."""
    return bool(traits_of(planner).drives_itself)


def requires_log(planner) -> bool:
    """Whether `planner` declares that it needs the recorded episode (`set_log`)."""
    return bool(traits_of(planner).requires_log)


def shape_problem(plan: Plan) -> str | None:
    """Why `plan` cannot be tracked at all (wrong shape, NaN/inf, a step under MIN_PLAN_DT_S,
    speeds that do not match the waypoints), None if it can."""
    waypoints = np.asarray(plan.waypoints, dtype=np.float64)
    if not plan.timed:
        if waypoints.shape != (PLAN_STEPS, 2):
            return (f"Plan.waypoints has shape {waypoints.shape}; the contract is [12, 2] (6 s at "
                    "0.5 s), or set Plan.dt_s / Plan.speeds for a timed plan")
    else:
        dt = float(plan.dt_s)
        if not np.isfinite(dt) or dt < MIN_PLAN_DT_S - 1e-9:
            return f"Plan.dt_s is {plan.dt_s!r}; a timed plan's step is at least {MIN_PLAN_DT_S} s"
        if waypoints.ndim != 2 or waypoints.shape[1] != 2 or len(waypoints) < 1:
            return f"Plan.waypoints has shape {waypoints.shape}; a timed plan is [K >= 1, 2]"
        if plan.speeds is not None:
            speeds = np.asarray(plan.speeds, dtype=np.float64)
            if speeds.shape != (len(waypoints),) or not np.isfinite(speeds).all():
                return (f"Plan.speeds has shape {speeds.shape} or non-finite values; expected "
                        f"finite [{len(waypoints)}] (one m/s per waypoint)")
    if not np.isfinite(waypoints).all():
        return "Plan.waypoints holds NaN or inf; every waypoint must be finite"
    return None


def check_plan(plan: Plan, name: str) -> Plan:
    """`plan` if it can be tracked; InputError naming the planner and why not otherwise."""
    problem = shape_problem(plan)
    if problem is not None:
        raise InputError(f"planner {name} returned a plan that cannot be tracked: {problem}")
    return plan


class HumanDriver:
    """Marker for `idm`: the simulator's IDM/MOBIL ego keeps driving itself."""

    name = "idm"
    drives_itself = True     # the rollout neither hands the ego over nor asks for plans
