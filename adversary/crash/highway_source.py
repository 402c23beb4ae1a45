"""The source of highway-env attack scenes (adversary.crash.scene_source).

Every other vehicle replays the spliced log (`LogReplayEpisode`), the ego is handed to the
planner at t = 0 (`replay` plays the human back) and the whole log is driven, as `riskmap
evaluate --mode log` drives it. highway-env's own contact response is switched off for the ego:
STRIVE judges box overlap, so the ego passes through the other box and the drive goes on.
"""

from __future__ import annotations

from dataclasses import dataclass

from adversary.crash.scenes import WINDOW_DT_S, AttackScene, SceneRecord, record_attack_scene
from rasterize.timebase import FUTURE_S, HISTORY_S
from rasterize.tracks import Tracks
from riskmap.sim.records.failures import HIGHWAY_ENV_LIMITS
from riskmap.sim.worlds.log_replay import HumanLog


def _no_contact_response(run) -> None:
    # highway-env would push the ego out of any box it touches and stop the episode; STRIVE
    # judges overlap, so the ego passes through and the boxes are measured.
    run.ego.collidable = False


@dataclass
class HighwayWorld:
    """One drive of a highway-env scene (`SceneWorld`); `run` is its `LogReplayEpisode`."""

    run: object
    driver: object
    loop: object
    hooks: object
    episode: int
    source: str            # the scenes' `source` (the env id)

    def record(self, loop_record) -> dict:
        from riskmap.sim.worlds.highway_drive import episode_record

        return episode_record(self.run, self.driver, loop_record, self.episode)

    def tracks(self) -> tuple[Tracks, int]:
        tracks = self.run.recorder.tracks()
        return (Tracks(tracks.states.copy(), tracks.valid.copy(), tracks.sizes.copy(), tracks.kinds.copy(),
                       self.run.log_ids()), self.run.recorder.ego_id)

    def final_scene(self):
        recorder = self.run.recorder
        return recorder.scene(recorder.num_steps - 1, history_s=self.run.time_s, future_s=0.0,
                              dt_s=recorder.dt_s, source=self.source)

    def window(self, step: int):
        # `riskmap collect`'s windows: 2 s of history, 6 s of future at 2 Hz
        return self.run.recorder.scene(step, HISTORY_S, FUTURE_S, WINDOW_DT_S, source=self.source)


@dataclass(frozen=True)
class HighwaySource:
    limits = HIGHWAY_ENV_LIMITS

    def record(self, scene: AttackScene, family: str | None = None) -> SceneRecord:
        # the IDM/MOBIL human driven on the seeded episode, at 10 Hz (CRASH's judge drives at its own rates)
        return record_attack_scene(scene)

    def world(self, record: SceneRecord, log: HumanLog, planner, planner_spec: str, control_hz: int,
              replan_hz: int) -> HighwayWorld:
        from riskmap.sim.loop.plan import requires_log
        from riskmap.sim.loop.rollout import DriveHooks
        from riskmap.sim.worlds.episode import cached_env
        from riskmap.sim.worlds.highway_drive import DriveConfig
        from riskmap.sim.worlds.log_replay import LogReplayEpisode

        scene = record.scene
        env = cached_env(scene.env_id, control_hz)
        replay = requires_log(planner)
        if replay:
            planner.set_log(log)          # the ego's own record is never spliced
        run = LogReplayEpisode(env, scene.env_id, scene.scene_seed, scene.episode, log, control_hz,
                               replay_ego=replay, static_agents=scene.static_agents)
        config = DriveConfig(scene.env_id, 1, scene.scene_seed, control_hz, replan_hz,
                             episode_s=(log.num_steps - 1) * log.dt_s)
        return HighwayWorld(run, planner, config.loop(), DriveHooks(on_ready=(_no_contact_response,)),
                            scene.episode, scene.env_id)

    def handover_step(self, record: SceneRecord) -> int:
        return 0                          # the planner drives the whole log


HIGHWAY_SOURCE = HighwaySource()
