"""`riskmap check-planner`: every deliberate breach of the planner contract is named, a good
planner passes."""

import numpy as np
import pytest

from riskmap.cli import main
from riskmap.evaluation.check_planner import CheckConfig, check_planner, plan_problems
from riskmap.sim.loop.plan import Plan

QUICK = CheckConfig(envs=("highway-v0",), episode_s=2.0)
SPEC = "py:tests.broken_planners:Broken?fault={}"


@pytest.mark.parametrize("fault, says", [
    ("world_frame", "ego frame"),
    ("kmh", "km/h"),
    ("nan", "NaN"),
    ("shape", "shape (6, 2)"),
    ("raise", "plan() raised RuntimeError: this planner always fails"),
    ("unseeded", "same SPEC and seed"),
    ("not_a_plan", "not a riskmap.sim.loop.plan.Plan"),
    ("swapped_axes", "swapped axes"),
])
def test_each_breach_is_named(fault, says):
    findings = check_planner(SPEC.format(fault), QUICK)
    assert any(says in line for line in findings.lines()), findings.lines()


def test_a_slow_planner_is_named():
    findings = check_planner(SPEC.format("slow"), CheckConfig(envs=("highway-v0",), episode_s=0.5,
                                                              determinism_scenes=0))
    assert any("the loop replans every 500 ms" in line for line in findings.lines())


def test_a_planner_that_keeps_the_contract_passes_and_the_cli_says_so(capsys):
    assert not check_planner(SPEC.format("none"), QUICK).counts
    assert main(["check-planner", "cv", "--envs", "highway-v0,intersection-v0", "--seconds", "2",
                 "--quiet"]) == 0
    assert "keeps the planner contract" in capsys.readouterr().out


def test_the_cli_prints_one_line_per_breach_and_exits_1(capsys):
    assert main(["check-planner", SPEC.format("world_frame"), "--envs", "highway-v0",
                 "--seconds", "2", "--quiet"]) == 1
    broken = [line for line in capsys.readouterr().out.splitlines() if line.startswith("BROKEN")]
    assert len(broken) == 1 and "not world coordinates" in broken[0]


def test_plan_problems_units():
    ahead = np.stack([10.0 * 0.5 * np.arange(1, 13), np.zeros(12)], axis=1)
    assert plan_problems(Plan(ahead), speed=10.0) == []
    assert "km/h" in plan_problems(Plan(ahead * 3.6), speed=10.0)[0]
    sprint = ahead.copy()
    sprint[6:] += np.arange(1, 7)[:, None] * [40.0, 0.0]
    assert "imply" in plan_problems(Plan(sprint), speed=10.0)[0]
    stopped = np.zeros((12, 2))
    assert plan_problems(Plan(stopped), speed=0.0) == []


FIXTURES = __import__("pathlib").Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"


def test_the_contract_is_checked_on_recordings_too(capsys):
    """check-planner --commonroad: the planner drives recorded vehicles as evaluate --commonroad
    drives them, and its breaches are named with the recording and vehicle."""
    findings = check_planner(SPEC.format("world_frame"), CheckConfig(recordings=(str(FIXTURES),),
                                                                     determinism_scenes=0))
    assert findings.plans > 0 and any("not world coordinates" in line and "vehicle" in line
                                      for line in findings.lines()), findings.lines()
    assert main(["check-planner", "cv", "--commonroad", str(FIXTURES), "--quiet"]) == 0
    assert "keeps the planner contract" in capsys.readouterr().out


class _Attached:
    """Plans constant velocity; says whether the loop handed it the world (`attach`)."""

    worlds: list = []

    def __init__(self, seed: int = 0):
        pass

    def reset(self, scene) -> None:
        pass

    def attach(self, world) -> None:
        _Attached.worlds.append(world)

    def plan(self, scene) -> Plan:
        speed = float(scene.ego_state()[4])
        return Plan(np.stack([speed * 0.5 * np.arange(1, 13), np.zeros(12)], axis=1))


def test_the_checked_planner_declares_through_the_checking_wrapper():
    # what it declares (here `attach`) reaches the loop as in every other command
    _Attached.worlds.clear()
    findings = check_planner(f"py:{__name__}:_Attached", CheckConfig(envs=("highway-v0",), episode_s=1.0,
                                                                     determinism_scenes=0))
    assert not findings.counts and len(_Attached.worlds) == 1


class _Stuck(_Attached):
    """No solution at every other replan: within the contract."""

    def __init__(self, seed: int = 0):
        self.calls = 0

    def plan(self, scene) -> Plan:
        from riskmap.sim.loop.plan import NoSolution

        self.calls += 1
        if self.calls % 2 == 0:
            raise NoSolution("boxed in")
        return super().plan(scene)


def test_no_solution_is_counted_apart_not_as_a_breach():
    findings = check_planner(f"py:{__name__}:_Stuck", CheckConfig(envs=("highway-v0",), episode_s=2.0))
    assert not findings.counts, findings.lines()
    assert findings.no_solution == 2 and "boxed in" in findings.no_solution_first


def test_check_planner_prints_the_replans_without_a_solution(capsys):
    assert main(["check-planner", f"py:{__name__}:_Stuck", "--envs", "highway-v0", "--seconds", "2",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "2 of 4 replans without a solution (the ego braked), first on highway-v0" in out
    assert "boxed in" in out and "keeps the planner contract" in out
