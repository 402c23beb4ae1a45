"""The planner contract's plan checks inside the rollout loop: every plan is checked, an
implausible one is counted in the episode record and still driven as made."""

from __future__ import annotations

import pytest

from riskmap.sim.episode import cached_env
from riskmap.sim.plan_checks import ImplausiblePlans, implausible_note, summarise_implausible
from riskmap.sim.record import EpisodeRecord
from riskmap.sim.rollout import DriveConfig, drive_episode
from tests.broken_planners import Broken

ENV = "highway-v0"
CONFIG = DriveConfig(ENV, 1, episode_s=2.0)
# What a plan's time changes, run to run: left out where drives are compared.
TIMES = ("plan_ms_median", "plan_ms_mean", "plan_ms_p90")


def _drive(fault: str) -> dict:
    return drive_episode(cached_env(ENV), Broken(fault), CONFIG, 0)


def _unchecked(monkeypatch, fault: str) -> dict:
    """The drive with the loop's checks switched off: what the loop did before it checked."""
    with monkeypatch.context() as patch:
        patch.setattr(ImplausiblePlans, "check", lambda self, plan, scene: None)
        return _drive(fault)


def _measured(record: dict) -> dict:
    return {k: v for k, v in record.items()
            if k not in TIMES and k not in ("implausible_plans", "implausible_plan_first")}


def test_km_h_plans_are_counted_with_the_first_message_and_driven_as_made(monkeypatch):
    record = _drive("kmh")
    assert record["implausible_plans"] == record["plan_calls"] == 4
    assert record["implausible_plan_first"].startswith("at 0.0 s: the first step implies 90.0 m/s")
    assert "km/h" in record["implausible_plan_first"]
    assert _measured(record) == _measured(_unchecked(monkeypatch, "kmh"))


def test_a_planner_that_keeps_the_contract_counts_none_and_drives_bit_identically(monkeypatch):
    record = _drive("none")
    assert record["implausible_plans"] == 0 and record["implausible_plan_first"] is None
    assert _measured(record) == _measured(_unchecked(monkeypatch, "none"))


def test_a_self_driving_ego_makes_no_plan_to_check():
    record = drive_episode(cached_env(ENV), type("SelfDriving", (), {"drives_itself": True})(), CONFIG, 0)
    assert record["plan_calls"] == 0 and record["implausible_plans"] == 0


def test_records_from_before_the_count_read_as_0_and_summaries_say_n_a():
    assert EpisodeRecord.from_dict({"planner": "cv", "collided": False}).implausible_plans == 0
    old = [{"episode": 0}, {"episode": 1, "implausible_plans": 0}]
    assert summarise_implausible(old, str)["implausible_plans"] is None
    assert implausible_note({"cv": (summarise_implausible(old, str), 2)}) == ""


@pytest.mark.parametrize("counts, expected", [((0, 0), ""), ((3, 0), "kmh: 3 plans in 1 of 2 episodes")])
def test_the_note_under_a_table_names_only_planners_with_implausible_plans(counts, expected):
    records = [{"episode": e, "implausible_plans": n,
                "implausible_plan_first": "at 0.0 s: km/h?" if n else None} for e, n in enumerate(counts)]
    summary = summarise_implausible(records, lambda r: f"in episode {r['episode']}")
    note = implausible_note({"kmh": (summary, 2), "cv": (summarise_implausible(records[1:], str), 1)})
    assert (expected in note) if expected else note == ""
    if expected:
        assert "first in episode 0 at 0.0 s: km/h?" in note and "cv" not in note
