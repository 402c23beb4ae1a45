"""The one per-episode record: its flat dict, reading it back, and reading records stored under
the old names."""

import json
import math

import pytest

from riskmap.sim.records.record import CORE_FIELDS, EpisodeRecord, current_names


def _record(**changes) -> EpisodeRecord:
    values = dict(planner="ConstantVelocityPlanner", collided=False, off_road=True, simulated_s=3.0,
                  distance_m=61.5, mean_speed_mps=20.5, min_gap_m=7.25, plan_calls=6,
                  plan_ms_median=1.5, plan_ms_mean=1.75, plan_ms_p90=2.5,
                  extra={"episode": 4, "env_seed": 9, "collision": {"other_id": 3}})
    values.update(changes)
    return EpisodeRecord(**values)


def test_as_dict_is_flat_core_first_and_round_trips_through_json():
    record = _record()
    flat = record.as_dict()
    assert tuple(flat)[:len(CORE_FIELDS)] == CORE_FIELDS
    assert flat["episode"] == 4 and "extra" not in flat
    assert EpisodeRecord.from_dict(json.loads(json.dumps(flat))) == record


def test_old_names_are_read_as_the_new_ones():
    old = {"planner": "cv", "collided": True, "ego_off_road": False, "progress_m": 42.0,
           "min_gap_m": None, "attack": "natural"}
    assert current_names(old) == {"planner": "cv", "collided": True, "off_road": False,
                                  "distance_m": 42.0, "min_gap_m": None, "attack": "natural"}
    assert "progress_m" in old                      # the stored record is left as it was
    record = EpisodeRecord.from_dict(old)
    assert record.distance_m == 42.0 and record.off_road is False and record.extra == {"attack": "natural"}
    assert current_names({"ego_progress_m": 3.0})["distance_m"] == 3.0      # the CRASH judge's name


def test_a_gap_of_inf_is_none_in_records_old_and_new():
    assert _record(min_gap_m=math.inf).as_dict()["min_gap_m"] is None
    assert EpisodeRecord.from_dict({"min_gap_m": float("inf")}).min_gap_m is None
    measured = EpisodeRecord.measured("cv", False, False, 1.0, 10.0, [10.0], [math.inf, math.inf], [])
    assert measured.min_gap_m is None and measured.plan_ms_p90 is None and measured.plan_calls == 0
    json.dumps(measured.as_dict(), allow_nan=False)


def test_an_extra_may_not_reuse_a_core_name():
    with pytest.raises(ValueError, match="distance_m"):
        _record(extra={"distance_m": 1.0}).as_dict()


def test_an_old_and_a_new_name_that_disagree_are_refused():
    with pytest.raises(ValueError, match="progress_m"):
        current_names({"progress_m": 1.0, "distance_m": 2.0})
    assert current_names({"progress_m": 2.0, "distance_m": 2.0}) == {"distance_m": 2.0}
