"""The report's "Guard on / off" numbers from hand-made records: what the guard did (interventions
over frames, hard brakes) and the sentence that says whether it acted when nothing changed."""

from adversary.report.numbers import report_numbers
from tests.adversary.report.test_report_sections import _record


def _pair(attack, category, off, on, guard=None, old=False):
    """Two jobs of cv and two of guard:cv; `off` / `on`: whether each job collided; `guard`:
    (frames, interventions, hard) per guarded job; `old`: records without the guard's fields."""
    out = []
    for planner, outcomes in (("cv", off), ("guard:cv", on)):
        for episode, collided in enumerate(outcomes):
            counts = guard[episode] if planner == "guard:cv" and guard else None
            record = _record(f"{planner}-{attack}-{episode}".replace(":", "-"), planner, attack, category,
                             collided, guard=counts)
            if old:
                for key in ("guard_frames", "guard_interventions", "guard_hard"):
                    del record[key]
            out.append(record)
    return out


def _guard_rows():
    records = (_pair("natural", "baseline", (False, False), (False, False), [(12, 3, 1), (8, 2, 0)])
               + _pair("rule_a", "rule", (True, False), (True, False), [(6, 0, 0), (4, 0, 0)])
               + _pair("rule_b", "rule", (True, True), (False, True), [(6, 2, 2), (6, 1, 0)])
               + _pair("rule_c", "rule", (False, False), (False, False), old=True))
    # a failed guarded job holds no counts and no metrics: left out everywhere
    failed = {**_record("guard-cv-natural-9", "guard:cv", "natural", "baseline", False), "status": "error",
              "error": "RuntimeError: broke"}
    for key in ("guard_frames", "guard_interventions", "guard_hard"):
        del failed[key]
    results, _ = report_numbers(records + [failed], 0)
    return {row["attack"]: row for row in results["guard"]}, results


def test_the_guarded_row_holds_interventions_over_frames_and_hard_brakes():
    rows, results = _guard_rows()
    assert rows["natural"]["guard"] == {"jobs": 2, "frames": 20, "interventions": 5, "hard": 1,
                                        "intervention_ratio": 0.25}
    assert rows["rule_b"]["guard"]["intervention_ratio"] == 0.25 and rows["rule_b"]["guard"]["hard"] == 2
    assert rows["rule_c"]["guard"] is None                     # records from before the counts
    # one definition: the pair's numbers are the guarded row's of the comparison table
    comparison = {(r["planner"], r["attack"]): r for r in results["comparison"]}
    assert comparison["guard:cv", "natural"]["guard"] == rows["natural"]["guard"]
    assert comparison["cv", "natural"]["guard"] is None
    by_family = {(r["planner"], r["attack"]): r for r in results["by_family"]}
    assert by_family["guard:cv", "natural"]["guard"] == rows["natural"]["guard"]


def test_an_unchanged_outcome_says_whether_the_guard_acted():
    rows, _ = _guard_rows()
    assert rows["natural"]["identical"] and rows["rule_a"]["identical"] and rows["rule_c"]["identical"]
    assert "the guard intervened 5 times without changing the outcome" in rows["natural"]["note"]
    assert "5 of 20 frames, 1 hard brake)" in rows["natural"]["note"]
    assert "the guard never intervened (0 of 10 frames)" in rows["rule_a"]["note"]
    assert "no guard counts" in rows["rule_c"]["note"]
    assert rows["rule_b"]["identical"] is False and rows["rule_b"]["note"] is None


def test_a_guard_that_made_no_decision_says_so():
    records = _pair("natural", "baseline", (False,), (False,), [(0, 0, 0)])
    results, _ = report_numbers(records, 0)
    [row] = results["guard"]
    assert row["guard"]["frames"] == 0 and row["guard"]["intervention_ratio"] is None
    assert "the guard never intervened (it made no decision: 0 frames)" in row["note"]


def test_the_unguarded_side_is_cut_to_the_scenes_the_guarded_planner_drove():
    """cv drove highway and intersection, guard:cv highway only: off compares on highway alone."""
    highway = _record("cv-h", "cv", "natural", "baseline", False)
    intersection = {**_record("cv-i", "cv", "natural", "baseline", True), "env_id": "intersection-v0"}
    guarded = _record("guard-cv-h", "guard:cv", "natural", "baseline", False, guard=(10, 0, 0))
    results, _ = report_numbers([highway, intersection, guarded], 0)
    (pair,) = results["guard"]
    assert pair["off"]["collision_rate"]["k"] == 0 and pair["off"]["collision_rate"]["n"] == 1
    assert pair["off"]["failure_rate"]["n"] == 1 and pair["on"]["failure_rate"]["k"] == 0   # what counts, off and on
    assert pair["identical"] and "never intervened (0 of 10 frames)" in pair["note"]
    # the comparison table still holds both of cv's scenes
    comparison = {(r["planner"], r["attack"]): r for r in results["comparison"]}
    assert comparison["cv", "natural"]["collision_rate"]["n"] == 2
