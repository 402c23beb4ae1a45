"""An attack record driven again: the stored tracks against a planner, judged, with the ego's progress."""

import numpy as np

from adversary.crash.judge import braking_track, cached_planner, judge, rollout
from adversary.crash.redrive import redrive_attack
from adversary.crash.scenes import AttackScene, record_attack_scene

# Episode 9 of highway-v0 seed 0: window row 3 drives ahead of the ego in the lane the ego keeps.
SCENE, AHEAD = AttackScene("highway-v0", 0, 9), 3


def test_a_redrive_is_the_judged_rollout_of_the_stored_tracks():
    record = record_attack_scene(SCENE)
    tracks = braking_track(record, AHEAD, decel_mps2=8.0)[None]
    attack = {"tracks": tracks.tolist(), "metrics": {"spliced_rows": [AHEAD]}, "adversary_row": AHEAD}
    planner = cached_planner("replay")
    out = redrive_attack(record, attack, planner, "replay")
    metrics = judge(record, tracks, [AHEAD], AHEAD, planner, "replay",
                    result=rollout(record, tracks, [AHEAD], planner, "replay"))
    assert out["spec"] == "replay" and "guard" not in out      # the replayed human has no guard
    assert out["collision"] is metrics["collision"] is True
    assert out["collision_any"] and not out["collision_before_t0"]
    assert out["min_gap_m"] == metrics["min_gap_m"]
    assert out["progress_m"] > out["progress_to_collision_m"] > 0.0
    assert np.isfinite(out["rollout_s"])
