"""The black-box search's failures as hardening windows: the scenario driven again, a clear
alternative found on it, the ego that follows it never touching the target."""

import json

import numpy as np
import pytest

from adversary.harden.loop import HardenConfig, round_search_windows
from adversary.harden.search_windows import _drive, search_failure_windows
from adversary.search.scenarios import get_template
from rasterize.errors import InputError
from riskmap.sim.records.metrics import box_iou

CV_CUT_IN = {"planner": "cv", "template": "cut_in", "seed": 0, "episode_s": 10.0}


def _cut_in(**changed) -> np.ndarray:
    template = get_template("cut_in")
    p = dict(zip(template.names, template.neutral)) | changed
    return np.array([p[n] for n in template.names])


@pytest.mark.slow
def test_a_cut_in_the_ego_drove_into_becomes_windows_that_brake_clear_of_it():
    # 8 m ahead, 4 m/s slower, cutting in at 3 s and braking: a constant-velocity ego hits it
    values = _cut_in(gap_m=8.0, rel_speed_mps=-4.0, manoeuvre_time_s=3.0, brake_mps2=4.0)
    _, recorder = _drive(CV_CUT_IN, values)
    tracks = recorder.tracks()
    states, valid, sizes = tracks.states, tracks.valid, tracks.sizes
    ego = recorder.ego_id
    target = 1 - ego

    made = search_failure_windows(CV_CUT_IN, values)
    info = made.info
    assert info["demonstration"] == "alternative" and info["accel_mps2"] < 0
    assert len(made.scenes) == info["windows"] >= 3
    assert info["steps"][-1] <= info["collision_step"] and info["steps"][0] >= 20     # 2 s of history
    # the failed drive did overlap the target at the collision step (the judge's criterion)
    k = info["collision_step"]
    assert box_iou(states[ego, k], sizes[ego], states[target, k], sizes[target]) > 0.02
    for scene, step in zip(made.scenes, info["steps"]):
        now = scene.current_index
        assert scene.time_s == pytest.approx(step * 0.1)
        assert scene.valid[0, now:].all() and scene.states.shape[1] == now + 13
        for j in range(1, 13):     # the demonstrated future never touches where the target drove
            k = step + 5 * j
            if k < states.shape[1] and valid[target, k]:
                assert box_iou(scene.states[0, now + j], scene.sizes[0], states[target, k], sizes[target]) == 0.0
        # the ego is slower at the end of the demonstration than at its start: it braked
        assert scene.states[0, -1, 4] < scene.states[0, now, 4] or scene.states[0, now, 4] < 1.0


@pytest.mark.slow
def test_a_scenario_that_does_not_collide_gives_no_windows():
    made = search_failure_windows(CV_CUT_IN, _cut_in())          # the neutral cut-in: 25 m ahead, same speed
    assert made.scenes == () and made.info == {"windows": 0, "why": "the search's drive does not collide"}


@pytest.mark.slow
def test_a_collision_before_two_seconds_of_history_gives_no_windows_and_says_why():
    # cutting in 3 m ahead at 0.5 s, 8 m/s slower: contact at about 0.9 s, before any window fits
    made = search_failure_windows(CV_CUT_IN, _cut_in(gap_m=3.0, rel_speed_mps=-8.0, manoeuvre_time_s=0.5,
                                                     brake_mps2=6.0))
    assert made.scenes == () and made.info["collision_step"] < 20
    assert made.info["why"] == "the collision comes before a window's 2 s of history"


@pytest.mark.slow
def test_a_round_searches_the_current_planner_and_resumes_without_redoing(tmp_path):
    config = HardenConfig(checkpoint="checkpoints/riskmap_highway", scenes="unused", natural="unused",
                          out=str(tmp_path), search_templates=("cut_in",), search_pop=4, search_gen=1)
    shards, found = round_search_windows(config, 1, progress=False)
    records = [json.loads(p.read_text()) for p in sorted((tmp_path / "round_1/search/cut_in/evaluations").glob("*.json"))]
    assert json.loads((tmp_path / "round_1/search/cut_in/run.json").read_text())["config"]["seed"] == 1
    assert found == {"cut_in": {"evaluations": len(records),
                                "collisions": sum(r["feasible"] and r["collided"] for r in records)}}
    assert len(shards) == found["cut_in"]["collisions"]
    assert all(s.with_suffix(".json").exists() for s in shards)
    assert sum(json.loads(s.with_suffix(".json").read_text())["windows"] for s in shards) > 0
    written = {s: s.with_suffix(".json").stat().st_mtime_ns for s in shards}
    assert round_search_windows(config, 1, progress=False) == (shards, found)
    assert {s: s.with_suffix(".json").stat().st_mtime_ns for s in shards} == written


def test_an_unknown_search_template_is_a_one_line_error():
    with pytest.raises(InputError, match="unknown template 'cutin'"):
        HardenConfig(checkpoint="c", scenes="s", natural="n", out="o", search_templates=("cutin",))
    with pytest.raises(InputError, match="--search-pop must be at least 1"):
        HardenConfig(checkpoint="c", scenes="s", natural="n", out="o", search_pop=0)
