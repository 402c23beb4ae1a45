"""Report sections for attacks and planners that other modules add (selection, search, guard),
rendered from hand-made records: each section appears when such records exist."""

import json

from adversary.attacks.registry import NaturalEpisode, NaturalParams, register_attack
from adversary.campaign.config import campaign_from_dict
from adversary.campaign.store import ResultStore
from adversary.report.check import page_summary, report_problems
from adversary.report.page import make_report
from riskmap.infra.config_mapping import to_plain


def _record(job_id, planner, attack, category, collided, extra=None, guard=None):
    return {**dict(zip(("guard_frames", "guard_interventions", "guard_hard"), guard or (None,) * 3)),"job_id": job_id, "planner": planner, "env_id": "highway-v0", "scene_seed": 0,
            "episode": 0, "attack": attack, "attack_name": attack, "attack_category": category,
            "attack_params": {}, "status": "ok", "error": None, "collided": collided,
            "off_road": False, "has_adversary": category != "baseline",
            "collided_with_adversary": collided and category != "baseline",
            "collision_type": "sideswipe" if collided else None, "collision_time_s": 1.0 if collided else None,
            "kinematic_mps": 4.0 if collided else None,
            "adversary_off_road": False if category != "baseline" else None, "other_off_road": False,
            "encounters": 10, "dangerous_encounters": 3 if collided else 1,
            "safety_pct": 30.0 if collided else 10.0, "solution_found": True if collided else None,
            "distance_m": 50.0, "attack_extra": extra or {}, "timing": {"wall_s": 1.0}}


def test_selection_search_and_guard_sections_render(tmp_path):
    for name, category in (("test_selection", "selection"), ("test_search", "search")):
        register_attack(name, NaturalParams, lambda params, seed: NaturalEpisode(), category, name)
    config = campaign_from_dict({
        "name": "sections", "planners": ["cv", "guarded:cv"],
        "scenarios": [{"env": "highway-v0", "episodes": 2}],
        "attacks": [{"name": "natural"}, {"name": "test_selection"}, {"name": "test_search"}]})
    search_extra = {"generations": [{"evaluations": 4, "collisions": 0}, {"evaluations": 4, "collisions": 2}],
                    "pareto_front": [[1.0, 3.0], [2.0, 1.5]], "objective_names": ["distance", "alteration"]}
    records = []
    for planner in ("cv", "guarded:cv"):
        for episode in (0, 1):
            for attack, category in (("natural", "baseline"), ("test_selection", "selection"),
                                     ("test_search", "search")):
                collided = category != "baseline" and (planner == "cv" or episode == 0)
                # the guard: idle on the natural episodes, 4 of 16 frames (1 hard) on the search's
                guard = None if planner == "cv" else (
                    (8, 0, 0) if category == "baseline" else (8, 3 - 2 * episode, 1 - episode))
                records.append(_record(f"{planner}-{attack}-{episode}".replace(":", "-"), planner, attack,
                                       category, collided, search_extra if category == "search" else None,
                                       guard))
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "campaign.json").write_text(json.dumps(
        {"config": to_plain(config), "jobs": [r["job_id"] for r in records]}))
    store = ResultStore(tmp_path / "c")
    for r in records:
        store.put(r, None)
    store.close()

    report = make_report(tmp_path / "c")
    results = report["results"]
    assert [(r["attack"], r["planner"]) for r in results["crash_ablation"]] == [
        ("test_selection", "cv"), ("test_selection", "guarded:cv")]
    assert results["crash_ablation"][0]["collision_rate"]["value"] == 1.0
    assert results["crash_ablation"][1]["collision_rate"]["value"] == 0.5
    guard = {row["attack"]: row for row in results["guard"]}
    assert guard["test_search"]["off"]["collision_rate"]["k"] == 2
    assert guard["test_search"]["on"]["collision_rate"]["k"] == 1
    assert guard["test_search"]["guard"] == {"jobs": 2, "frames": 16, "interventions": 4, "hard": 1,
                                             "intervention_ratio": 0.25}
    assert guard["test_search"]["identical"] is False and guard["test_search"]["note"] is None
    assert guard["natural"]["identical"] is True
    assert "the guard never intervened (0 of 16 frames)" in guard["natural"]["note"]
    unguarded = {(r["planner"], r["attack"]): r["guard"] for r in results["comparison"]}
    assert unguarded["cv", "natural"] is None and unguarded["guarded:cv", "natural"]["frames"] == 16
    assert report["images"]["search"] == "figures/search.png"
    page = tmp_path / "c" / "report.html"
    assert "Not run in this campaign" not in page.read_text()
    ids = {t["id"]: t["rows"] for t in page_summary(page)["tables"]}
    assert ids["crash-ablation"] == 2 and ids["search"] == 2 and ids["guard"] == 3
    text = page.read_text()
    assert "<th>interventions / frames (on)</th><th>hard brakes (on)</th>" in text
    assert "<td>4 / 16 (25.0%)</td>" in text and "<td>0 / 16 (0.0%)</td>" in text
    notes = text.split('<ul id="guard-notes" class="note">')[1].split("</ul>")[0]
    assert notes.count("<li>") == 1 and "cv, natural: guard on and off give identical results" in notes
    job_pages = tmp_path / "c" / "jobs"
    assert "The guard intervened in 3 of its 8 decision frames (1 hard brake)." in (
        job_pages / "guarded-cv-test_search-0.html").read_text()
    assert 'id="guard"' not in (job_pages / "cv-test_search-0.html").read_text()
    assert report_problems(page) == []
