"""What a guard did, in a job record: `guard_counts` reads a guarded planner's counts (also through
the report's recording wrapper), every attack puts them in its record, unguarded planners get None."""

import pytest

from adversary.attacks.crash import crash_record
from adversary.attacks.episode import GUARD_FIELDS, RecordingPlanner, clear_guard, guard_counts, record_of
from riskmap.sim.records.record import EpisodeRecord
from tests.adversary.attacks.conftest import NeverPlans

NONE = dict.fromkeys(GUARD_FIELDS)


class _StubGuard:
    """Answers `summary()` as `riskmap.guard.guarded.Guard` does (the keys the record reads)."""

    def __init__(self, summary):
        self._summary = dict(summary)
        self.resets = 0

    def summary(self):
        return dict(self._summary)

    def reset(self):
        self.resets += 1
        self._summary = {"frames": 0, "interventions": 0, "hard": 0}


class _GuardedStub(NeverPlans):
    def __init__(self, guard):
        self.guard = guard


class _Plain:
    def reset(self, scene):
        pass


SUMMARY = {"frames": 12, "interventions": 5, "intervention_ratio": 5 / 12, "single": 3,
           "sustained": 1, "hard": 1, "system1_ms": [], "system2_ms": []}
COUNTS = {"guard_frames": 12, "guard_interventions": 5, "guard_hard": 1}


def test_guard_counts_of_a_guarded_planner_and_through_the_recording_wrapper():
    planner = _GuardedStub(_StubGuard(SUMMARY))
    assert guard_counts(planner) == COUNTS
    assert guard_counts(RecordingPlanner(planner)) == COUNTS


@pytest.mark.parametrize("planner", [None, _Plain(), RecordingPlanner(_Plain()),
                                     _GuardedStub(True), _GuardedStub(None)])
def test_unguarded_planners_have_no_counts(planner):
    assert guard_counts(planner) == NONE


def test_a_summary_without_hard_brakes_counts_none():
    planner = _GuardedStub(_StubGuard({"frames": 4, "interventions": 2}))
    assert guard_counts(planner) == {"guard_frames": 4, "guard_interventions": 2, "guard_hard": 0}


def test_clear_guard_zeroes_the_counts_of_an_earlier_drive():
    guard = _StubGuard(SUMMARY)
    clear_guard(RecordingPlanner(_GuardedStub(guard)))
    assert guard.resets == 1
    assert guard_counts(_GuardedStub(guard)) == {"guard_frames": 0, "guard_interventions": 0, "guard_hard": 0}
    clear_guard(_Plain())                      # no guard: nothing to do


def test_the_real_guards_summary_is_what_the_record_reads():
    """GuardedPlanner with the "always" trigger (no checkpoint): its Guard's log and frames."""
    from riskmap.guard.guarded import GuardConfig, GuardedPlanner

    class Agent:
        def reset(self):
            pass

    planner = GuardedPlanner(_Plain(), None, Agent(), GuardConfig(trigger="always"))
    guard = planner.guard
    guard.frames = 7
    guard.log += [{"mode": "single"}, {"mode": "hard"}, {"mode": "hard"}, {"mode": "sustained"}]
    assert guard_counts(RecordingPlanner(planner)) == {"guard_frames": 7, "guard_interventions": 4,
                                                       "guard_hard": 2}
    clear_guard(planner)
    assert guard_counts(planner) == {"guard_frames": 0, "guard_interventions": 0, "guard_hard": 0}


class _Monitor:
    collision_step = None

    def summary(self):
        return {"has_adversary": False, "safety_pct": 10.0}


def _episode() -> dict:
    return {**EpisodeRecord("X", False, False, 3.0, 30.0, 10.0, None, 6, 1.0, 1.0, 1.0).as_dict(),
            "env_seed": 4, "episode": 0, "driver": "X"}


def test_record_of_writes_the_counts_flat_beside_the_other_fields():
    record = record_of(_episode(), _Monitor(), {}, RecordingPlanner(_GuardedStub(_StubGuard(SUMMARY))))
    assert {k: record[k] for k in GUARD_FIELDS} == COUNTS
    assert record["env_seed"] == 4 and record["attack_extra"] == {}
    unguarded = record_of(_episode(), _Monitor(), {})
    assert {k: unguarded[k] for k in GUARD_FIELDS} == NONE


def test_a_crash_record_holds_the_final_drives_counts_only_when_attacked():
    not_attacked = crash_record({"status": "no_candidate", "selector": "distance", "p": [0.0, 0.0],
                                 "candidates": 0, "agents": 2, "seconds": 1.0}, 8.0, COUNTS)
    assert not_attacked["attacked"] is False
    assert {k: not_attacked[k] for k in GUARD_FIELDS} == NONE


@pytest.mark.slow
def test_campaign_jobs_record_what_the_guard_did():
    """guard-always:SPEC (no checkpoint needed) beside cv, on the episode attacks, the search and
    CRASH (the final, judged drive: 8 s)."""
    from adversary.campaign.config import campaign_from_dict
    from adversary.campaign.job import run_job

    config = campaign_from_dict({
        "name": "guard", "seed": 0, "planners": ["cv", "guard-always:cv", "guard-always:idm"],
        "scenarios": [{"env": "highway-v0", "seed": 0, "episodes": 1}],
        "attacks": [{"name": "natural"}, {"name": "aggressive_neighbour", "params": {"selection": "nearest"}},
                    {"name": "random_search",
                     "params": {"template": "cut_in", "pop": 2, "generations": 1, "episode_s": 3.0}},
                    {"name": "crash", "params": {"selector": "distance", "iterations": 4, "replan_every": 2}}],
        "budget": {"episode_s": 2.0}})
    for job in config.jobs():
        record = run_job(job)["record"]
        assert record["status"] == "ok", record["error"]
        counts = {k: record[k] for k in GUARD_FIELDS}
        if job.planner == "cv":
            assert counts == NONE
            continue
        # one decision per 0.5 s of the drive the record is of (the search: its replay)
        assert counts["guard_frames"] == pytest.approx(2 * record["simulated_s"], abs=1), (job.attack, record)
        assert 0 <= counts["guard_hard"] <= counts["guard_interventions"] <= counts["guard_frames"]
        if job.planner == "guard-always:cv" and job.attack != "crash":
            assert counts["guard_frames"] == record["plan_calls"]
        if job.attack == "crash":
            assert record["attacked"] is True and counts["guard_frames"] == 16
