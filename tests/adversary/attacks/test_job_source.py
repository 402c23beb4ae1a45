"""One runner per attack entry: the job's scene source runs it against the job's kind of scene."""

from types import SimpleNamespace

import pytest

from adversary.attacks.base import HIGHWAY, RECORDED, AttackEntry
from adversary.attacks.job_source import HighwayJobs, RecordedJobs, job_source, run_entry
from adversary.attacks.registry import attack_entry
from rasterize.errors import InputError


def _job(scene=None, name="x"):
    return SimpleNamespace(scene=scene, attack_name=name, env_id="commonroad:us101" if scene else "highway-v0")


def test_the_job_names_its_source():
    assert isinstance(job_source(_job()), HighwayJobs) and job_source(_job()).kind == HIGHWAY
    assert isinstance(job_source(_job(scene=object())), RecordedJobs) and job_source(_job(object())).kind == RECORDED


def test_builtin_entries_declare_the_scenes_they_run_on():
    assert attack_entry("natural").scenes == attack_entry("crash").scenes == (HIGHWAY, RECORDED)
    assert attack_entry("aggressive_neighbour").scenes == (HIGHWAY,)


def test_hooks_other_than_a_baseline_cannot_claim_recorded_scenes():
    with pytest.raises(ValueError, match="highway-env world"):
        AttackEntry("rule", object, "rule", "", factory=lambda p, s: None, scenes=(HIGHWAY, RECORDED))
    with pytest.raises(ValueError, match="scenes"):
        AttackEntry("odd", object, "baseline", "", factory=lambda p, s: None, scenes=("mars",))


def test_run_entry_runs_the_job_or_refuses_its_kind():
    seen = []
    entry = AttackEntry("whole", object, "selection", "", run_job=lambda job: seen.append(job) or ({}, None),
                        scenes=(HIGHWAY, RECORDED))
    job = _job(scene=object(), name="whole")
    assert run_entry(entry, job) == ({}, None) and seen == [job]
    highway_only = AttackEntry("hw", object, "rule", "", factory=lambda p, s: None)
    with pytest.raises(InputError, match="needs a highway-env world; it cannot run on the recorded family"):
        run_entry(highway_only, _job(scene=object(), name="hw"))
