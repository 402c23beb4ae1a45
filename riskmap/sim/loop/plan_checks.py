"""The planner contract's sanity checks on one plan, and their count over an episode and a run.

`plan_problems` says what is wrong with a plan: not a `Plan`, wrong shape, NaN/inf, km/h instead
of m/s, world instead of ego coordinates, impossible speeds, swapped or backward axes. The
rollout (`riskmap.sim.loop.rollout`) runs it on every plan a planner makes and counts the failures in
`ImplausiblePlans`; `riskmap check-planner` names them one line each. A check is a few numpy
operations on 12 points (microseconds), against a replan period of 500 ms.

An implausible plan is still driven as made (the loop's tracking controller follows it): the
count says a run's numbers came from plans that break the contract, without changing the numbers
of any planner that keeps it. Wrong shape or non-finite waypoints cannot be tracked at all and
stop the episode (`riskmap.sim.loop.plan.check_plan`).

A timed plan (`Plan.dt_s`, `Plan.speeds`: any step >= 0.1 s) is checked the same way at its own
step. A planner that raises `riskmap.sim.loop.plan.NoSolution` (or, through an adapter, returns no
trajectory) made no plan: that is counted beside the implausible plans, in `no_solution` of the
same `ImplausiblePlans` (records: `no_solution_plans`, `no_solution_first`), so that it reaches
every record and summary the implausible count reaches; the loop brakes meanwhile.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from riskmap.sim.loop.plan import Plan, shape_problem

MAX_SPEED_MS = 60.0          # faster than any road vehicle here: the waypoints are not metres
MAX_ACCEL_MS2 = 10.0         # beyond hard braking: the first waypoint does not start at the ego
KMH_PER_MS = 3.6


def plan_problems(plan, speed: float) -> list[str]:
    """What is wrong with `plan` made at ego speed `speed` (m/s); empty if nothing."""
    if not isinstance(plan, Plan):
        return [f"plan() returned a {type(plan).__name__}, not a riskmap.sim.loop.plan.Plan"]
    try:
        problem = shape_problem(plan)
    except (TypeError, ValueError):
        return ["Plan.waypoints is not numeric; give a float array [12, 2]"]
    if problem is not None:
        return [problem]
    waypoints = np.asarray(plan.waypoints, dtype=np.float64)
    dt = float(plan.dt_s)
    return (_scale_problems(waypoints, speed, dt) + _axis_problems(waypoints, speed, dt)
            + _speed_problems(plan.speeds))


def _reach_m(speed: float, dt: float) -> float:
    """How far the first waypoint (`dt` s ahead) can be from the ego at `speed` (m/s)."""
    return speed * dt + 0.5 * MAX_ACCEL_MS2 * dt ** 2 + 1.0


def _scale_problems(waypoints: np.ndarray, speed: float, dt: float) -> list[str]:
    """Units and frame: km/h, world coordinates, impossible speeds (the first that applies)."""
    steps = np.linalg.norm(np.diff(np.vstack([[0.0, 0.0], waypoints]), axis=0), axis=1) / dt
    first = float(np.linalg.norm(waypoints[0]))
    if speed > 3.0 and abs(steps[0] / speed - KMH_PER_MS) < 0.4:
        return [(f"the first step implies {steps[0]:.1f} m/s at a speed of {speed:.1f} m/s "
                f"(3.6x: km/h?); the waypoints are metres {dt:g} s apart")]
    reach = _reach_m(speed, dt)
    if first > 2.0 * reach + 5.0:      # far beyond any overshoot: the frame is wrong
        return [(f"the first waypoint is {first:.0f} m from the ego at {speed:.1f} m/s; "
                "waypoints are in the ego frame (origin at the ego, x forward, y left), "
                "not world coordinates")]
    if first > reach:                  # a plan ahead of the car: the controller cannot follow it
        return [(f"the first waypoint is {first:.1f} m from the ego at {speed:.1f} m/s, beyond "
                 f"the {reach:.1f} m the car can cover in {dt:g} s; the plan runs ahead of the car")]
    if steps.max() > MAX_SPEED_MS:
        return [f"the waypoints imply {steps.max():.0f} m/s; they are metres {dt:g} s apart"]
    return []


def _axis_problems(waypoints: np.ndarray, speed: float, dt: float) -> list[str]:
    """In one second at speed no vehicle turns by more than about 60 degrees: the plan's first
    second must point forward (x), else its axes are not the ego frame's."""
    index = round(1.0 / dt) - 1
    if index >= len(waypoints):
        return []                       # a timed plan shorter than 1 s: nothing to judge by
    second = waypoints[index]
    if speed <= 3.0 or np.linalg.norm(waypoints[0]) > _reach_m(speed, dt) \
            or np.linalg.norm(second) <= 0.5 * speed:
        return []
    angle = np.degrees(abs(np.arctan2(second[1], second[0])))
    if angle > 120:
        return ["the plan runs backwards at speed; x points forward in the ego frame"]
    if angle > 60:
        return ["the plan runs sideways at speed; x is forward and y left (swapped axes?)"]
    return []


def _speed_problems(speeds) -> list[str]:
    """A timed plan's own speeds: never backwards, never beyond any road vehicle."""
    if speeds is None:
        return []
    speeds = np.asarray(speeds, dtype=np.float64)
    if speeds.min() < -0.1 or speeds.max() > MAX_SPEED_MS:
        return [f"Plan.speeds run from {speeds.min():.1f} to {speeds.max():.1f} m/s; they are m/s "
                f"forward, 0 to {MAX_SPEED_MS:.0f}"]
    return []


# The record fields of the counts (`riskmap.sim.records.record.EpisodeRecord`).
COUNT_FIELD, FIRST_FIELD = "implausible_plans", "implausible_plan_first"
NO_SOLUTION_FIELD, NO_SOLUTION_FIRST_FIELD = "no_solution_plans", "no_solution_first"


@dataclass
class ImplausiblePlans:
    """The plans of one episode (or several drives) that fail `plan_problems`: how many, and the
    first one's problems with the time of the scene it was made from; and the replans at which
    the planner had no plan at all (`no_solution`, `riskmap.sim.loop.plan.NoSolution`), with the first
    one's time and reason."""

    count: int = 0
    first: str | None = None
    no_solution: int = 0
    no_solution_first: str | None = None

    def check(self, plan: Plan, scene) -> None:
        """Count `plan` if it fails a check at the ego speed of `scene`, the scene it was made
        from (what the planner saw)."""
        problems = plan_problems(plan, float(scene.ego_state()[4]))
        if problems:
            self.add(1, f"at {scene.time_s:.1f} s: " + "; ".join(problems))

    def add(self, count: int, first: str | None) -> None:
        self.count += int(count)
        if self.first is None:
            self.first = first

    def add_no_solution(self, count: int, first: str | None) -> None:
        self.no_solution += int(count)
        if self.no_solution_first is None:
            self.no_solution_first = first

    def add_record(self, record: dict) -> None:
        """Add the counts of an episode record (a dict with `fields()`' keys)."""
        self.add(record.get(COUNT_FIELD) or 0, record.get(FIRST_FIELD))
        self.add_no_solution(record.get(NO_SOLUTION_FIELD) or 0, record.get(NO_SOLUTION_FIRST_FIELD))

    def fields(self) -> dict:
        return {COUNT_FIELD: self.count, FIRST_FIELD: self.first,
                NO_SOLUTION_FIELD: self.no_solution, NO_SOLUTION_FIRST_FIELD: self.no_solution_first}


def summarise_implausible(records: list[dict], where: Callable[[dict], str]) -> dict:
    """Over a run's episode records: implausible plans in all (None when a record predates the
    count), episodes with any, and the first message, prefixed by `where(record)`; the same for
    the replans without a plan (`no_solution_*`; a record from before that count holds 0)."""
    counts = [r.get(COUNT_FIELD) for r in records]
    flagged = [r for r in records if r.get(COUNT_FIELD)]
    stuck = [r for r in records if r.get(NO_SOLUTION_FIELD)]
    return {COUNT_FIELD: None if any(c is None for c in counts) else int(sum(counts)),
            "implausible_plan_episodes": len(flagged),
            FIRST_FIELD: f"{where(flagged[0])} {flagged[0][FIRST_FIELD]}" if flagged else None,
            NO_SOLUTION_FIELD: int(sum(r.get(NO_SOLUTION_FIELD) or 0 for r in records)),
            "no_solution_episodes": len(stuck),
            NO_SOLUTION_FIRST_FIELD: (f"{where(stuck[0])} {stuck[0][NO_SOLUTION_FIRST_FIELD]}"
                                      if stuck else None)}


def implausible_note(rows: dict, unit: str = "episodes") -> str:
    """The line under a results table naming each planner with implausible plans ({name:
    (summary, episodes)}, summaries of `summarise_implausible`), and one naming each planner that
    had no plan at some replans; "" when every count is 0. Lines, not columns: the counts are 0
    for every planner that keeps the contract."""
    parts = [f"{name}: {s[COUNT_FIELD]} plans in {s['implausible_plan_episodes']} of {n} {unit}, first "
             f"{s[FIRST_FIELD]}" for name, (s, n) in rows.items() if s.get(COUNT_FIELD)]
    stuck = [f"{name}: {s[NO_SOLUTION_FIELD]} replans in {s['no_solution_episodes']} of {n} {unit}, "
             f"first {s[NO_SOLUTION_FIRST_FIELD]}" for name, (s, n) in rows.items()
             if s.get(NO_SOLUTION_FIELD)]
    text = ""
    if parts:
        text += ("Implausible plans (they break the planner contract's checks, "
                 "docs/guide/your-own-planner.md, \"The planner contract\"; they were driven as "
                 "made): " + " | ".join(parts) + "\n")
    if stuck:
        text += ("No solution (the planner returned no trajectory; the ego braked until its next "
                 "plan): " + " | ".join(stuck) + "\n")
    return text
