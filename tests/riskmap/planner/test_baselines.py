import numpy as np

from riskmap.evaluation.drive import drive
from riskmap.registry import make_planner
from riskmap.sim.loop.plan import Planner
from riskmap.sim.worlds.highway_drive import DriveConfig
from tests.scenes import constant_velocity_scene


def test_constant_velocity_plan_hand_computed():
    planner = make_planner("cv")
    assert isinstance(planner, Planner)
    plan = planner.plan(constant_velocity_scene(ego_speed=2.0))
    np.testing.assert_allclose(plan.waypoints[:, 0], np.arange(1, 13) * 1.0)
    np.testing.assert_allclose(plan.waypoints[:, 1], 0.0)


def test_constant_velocity_drives_closed_loop(tmp_path):
    summary = drive(DriveConfig("highway-v0", episodes=1, seed=3, episode_s=5.0), "cv",
                    tmp_path / "cv", progress=False)["summary"]
    # 5 s at the initial ~25 m/s with no lane change: about 125 m unless it meets a leader.
    assert 60.0 < summary["distance_m"] < 140.0 and summary["off_road_rate"] == 0.0
