"""A guarded closed-loop drive gives the record it gave when the guard still patched the ego's
`command` and read the episode's recorder itself: the same interventions, from the same history
scenes, and the same drive."""

import numpy as np
import pytest

pytest.importorskip("agentspeak")

from riskmap.guard.guarded import GuardConfig, GuardedHumanDriver, GuardedPlanner, system2_config
from riskmap.guard.system2 import DecelerationAgent
from riskmap.planner.baselines import ConstantVelocityPlanner
from riskmap.sim.worlds.episode import make_env
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

# Every speed is "high", so that System 2 acts on each alert.
CONFIG = GuardConfig(trigger="tgat", speed_threshold_mps={"highway": 1.0})
DRIVE = DriveConfig("highway-v0", 1, seed=3, episode_s=4.0)
MODES = ["single", "single", "hard", "hard", "hard", "single"]
# What each drive measured, and a checksum of every history scene System 1 was shown.
REFERENCE = {
    "cv": {"distance_m": 77.9499999999999, "mean_speed_mps": 19.074999999999992,
           "min_gap_m": 4.186826705517827,
           "seen": [894.356376, 2388.878909, 3658.480624, 4977.707116, 6344.201724, 7755.779201,
                    8042.363352, 6375.050824]},
    "idm": {"distance_m": 78.78257333209129, "mean_speed_mps": 19.289038765460656,
            "min_gap_m": 3.777303146562387,
            "seen": [894.356376, 2389.057446, 3659.0201, 4978.725439, 6345.816804, 7758.108945,
                     8045.52567, 6378.985086]},
}


class NearPredictor:
    """Stands in for the TGAT: the closer a neighbour, the higher its score and the shorter its
    time to contact; remembers a checksum of each history it was shown."""

    alert_threshold = 0.5

    def __init__(self):
        self.seen = []

    def score(self, tracks, ego, neighbours, last_step, segment_steps):
        states, valid = tracks.states, tracks.valid
        self.seen.append(round(float(np.where(valid[..., None], states, 0.0).sum()), 6))
        d = np.array([np.linalg.norm(states[i, last_step, :2] - states[ego, last_step, :2])
                      for i in neighbours])
        return 1.0 / (1.0 + d / 20.0), d / 8.0


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["cv", "idm"])
def test_guarded_drive_record_is_unchanged(kind):
    predictor, agent = NearPredictor(), DecelerationAgent(system2_config(CONFIG))
    planner = (GuardedPlanner(ConstantVelocityPlanner(), predictor, agent, CONFIG) if kind == "cv"
               else GuardedHumanDriver(predictor, agent, CONFIG))
    record = drive_episode(make_env("highway-v0", 10), planner, DRIVE, 0)
    expected = REFERENCE[kind]
    assert [e["mode"] for e in planner.guard.log] == MODES
    assert predictor.seen == pytest.approx(expected["seen"], abs=1e-6)
    assert not record["collided"]
    for key in ("distance_m", "mean_speed_mps", "min_gap_m"):
        assert record[key] == pytest.approx(expected[key], rel=1e-12, abs=1e-12)
