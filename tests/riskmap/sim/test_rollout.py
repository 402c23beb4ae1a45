"""The one rollout loop on a highway-env episode: hand-over, replanning, and a self-driving ego."""

from __future__ import annotations

import numpy as np

from riskmap.sim.loop.plan import Plan
from riskmap.sim.loop.rollout import DriveHooks
from riskmap.sim.worlds.episode import Episode, cached_env
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode

ENV = "highway-v0"


class _Straight:
    """Holds the current speed straight ahead."""

    def reset(self, scene) -> None:
        self.reset_source = scene.source

    def plan(self, scene) -> Plan:
        speed = float(scene.ego_state()[4])
        return Plan(np.column_stack([speed * 0.5 * np.arange(1, 13), np.zeros(12)]))


class _SelfDriving:
    """Declares that the world's own ego drives (as `HumanDriver` does), without subclassing it."""

    drives_itself = True


def test_a_planner_is_handed_the_ego_and_replans_at_the_replan_rate():
    env = cached_env(ENV)
    planner, plans, egos, ends = _Straight(), [], [], []
    hooks = DriveHooks(on_plan=lambda run, scene, plan, k: plans.append((k, scene.source)),
                       on_ready=(lambda run: egos.append(type(run.ego).__name__),),
                       on_end=lambda run, loop: ends.append((run.time_s, len(loop.plan_times_s))))
    record = drive_episode(env, planner, DriveConfig(ENV, 1, episode_s=2.0), 0, hooks)
    assert egos == ["PlannedVehicle"] and planner.reset_source == ""
    assert plans == [(k, ENV) for k in (0, 5, 10, 15)] and record["plan_calls"] == 4
    assert ends == [(2.0, 4)]                                  # on_end once, after the last step
    assert record["planner"] == "_Straight" and record["simulated_s"] == 2.0
    assert record["distance_m"] > 0 and np.isfinite(record["min_gap_m"])


def test_a_planner_that_drives_itself_keeps_the_worlds_ego():
    env = cached_env(ENV)
    run = Episode(env, ENV, 0, 0)
    ego = run.ego
    record = drive_episode(env, _SelfDriving(), DriveConfig(ENV, 1, episode_s=1.0), 0, run=run)
    assert run.ego is ego and type(ego).__name__ == "IDMVehicle"
    assert record["planner"] == "idm" and record["plan_calls"] == 0
    assert record["plan_ms_median"] is None and record["simulated_s"] == 1.0
