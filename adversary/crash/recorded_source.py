"""The source of attack scenes cut from CommonRoad recordings (adversary.crash.scene_source).

The others follow the spliced log by time (`adversary.crash.recorded.log_traffic`) on the
recording's lanelets; the ego is the human's record up to t0 and is handed over to the planner
there (`AttackWorld`, a `CommonRoadWorld` that keeps driving through contacts: collisions are
judged on box overlap afterwards) and driven for the scene's horizon. `replay` plays the ego's
record back (its states are the log's); a planner that drives itself (the IDM/MOBIL `idm`) is the
recordings' IDM/MOBIL (`RecordedRouteIdmPlanner`), as `riskmap evaluate --commonroad` drives it.
The drive's arrays keep the highway source's contract: recorder ids are log agents.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from adversary.crash.recorded import (
    FINAL_SCENE_AGENTS,
    FINAL_SCENE_RADIUS_M,
    log_traffic,
    record_recorded_scene,
    recording_traffic,
    road_network,
)
from adversary.crash.scenes import HISTORY_S, WINDOW_DT_S, AttackScene, SceneRecord, window_rows
from rasterize.commonroad.config import CommonRoadSceneConfig
from rasterize.commonroad.lanes import lanes_from_lanelets
from rasterize.commonroad.tracks import RecordedTraffic
from rasterize.errors import InputError
from rasterize.frames import highway_env_from_world
from rasterize.scene import Scene
from rasterize.tracks import Tracks
from riskmap.sim.records.failures import CAR_LIMITS
from riskmap.sim.records.metrics import centre_off_lane
from riskmap.sim.worlds.commonroad_replay import CommonRoadWorld, ReplayConfig
from riskmap.sim.worlds.log_replay import HumanLog


class AttackWorld(CommonRoadWorld):
    """`CommonRoadWorld` for attacks: a contact does not end the episode (STRIVE judges box
    overlap over the whole horizon; the first contact is kept in `contact`), the road is built
    once per process, and with `replay_track` ([S, 6] log states) the ego plays that record back
    instead of driving; then leaving the lanes is noted but does not end the replay."""

    def __init__(self, traffic: RecordedTraffic, ego_id: int, start_s: float, duration_s: float,
                 config: ReplayConfig, scene_config: CommonRoadSceneConfig,
                 replay_track: np.ndarray | None = None):
        self.replay_track = replay_track
        self.contact: dict | None = None
        super().__init__(traffic, ego_id, start_s, duration_s, config, scene_config)
        self.start_step = round(self.start / self.dt)

    def _build_road(self):
        from highway_env.road.road import Road

        return Road(network=road_network(self.traffic.scenario.lanelet_network),
                    np_random=np.random.RandomState(0), record_history=False)

    @property
    def done(self) -> bool:
        if self.replay_track is not None:
            return self.steps >= self.n_steps
        return super().done

    def _move_ego(self) -> np.ndarray:
        if self.replay_track is None:
            return super()._move_ego()
        state = self.replay_track[self.start_step + self.steps + 1].copy()
        self.vehicle.position = highway_env_from_world(state[:2])
        self.vehicle.heading = float(-np.arctan2(state[3], state[2]))
        self.vehicle.speed = float(state[4])
        return state

    def step(self) -> None:
        super().step()
        if self.crashed:
            self.contact = self.contact or {**self.collision, "time_s": round(self.time_s, 3)}
            self.crashed, self.collision = False, None
            # CommonRoadWorld stops checking at a contact; the lane check still applies.
            if centre_off_lane(self.road, self.vehicle, self.config.off_road_margin_m):
                self.off_network = True


class _LogPlayback:
    """The ego plays its record back (`AttackWorld.replay_track`): no plans are made."""

    drives_itself = True
    name = "replay"

    def reset(self, scene: Scene) -> None:
        pass


def _driver(planner, traffic: RecordedTraffic, ego_id: int):
    """What drives the ego on a recording: log playback for a planner that needs the log, the
    recordings' IDM/MOBIL for one that drives itself, else the planner."""
    from riskmap.sim.drivers.recorded_idm import RecordedRouteIdmPlanner
    from riskmap.sim.loop.plan import drives_itself, requires_log

    if requires_log(planner):
        return _LogPlayback()
    if drives_itself(planner):
        return RecordedRouteIdmPlanner(traffic, ego_id)
    return planner


def _final_scene(traffic: RecordedTraffic, states: np.ndarray, valid: np.ndarray, ego: int,
                 dt_s: float, source: str) -> Scene:
    """The last step with the whole drive as history (as `TrafficRecorder.scene` cuts it)."""
    k = states.shape[1] - 1
    return _scene_at(traffic, states, valid, ego, dt_s, source, k, k, 0, 1, CommonRoadSceneConfig())


def _scene_at(traffic: RecordedTraffic, states: np.ndarray, valid: np.ndarray, ego: int, dt_s: float,
              source: str, k: int, history: int, future: int, stride: int, config: CommonRoadSceneConfig) -> Scene:
    """The drive at step `k` with `history` and `future` steps of `stride` log steps around it
    (times outside the drive invalid), as `TrafficRecorder.scene` cuts it; the route by `config`'s
    rule."""
    at_k = HumanLog(states, valid, traffic.sizes, traffic.kinds, ego, dt_s, False, False)
    agents = window_rows(at_k, k, FINAL_SCENE_RADIUS_M, FINAL_SCENE_AGENTS)
    state, others = states[ego, k], agents[1:]
    lanes = lanes_from_lanelets(traffic.scenario.lanelet_network, state[:2], config.lane_radius_m)
    route = traffic.route(ego, state, states[others, k], traffic.sizes[others, 0], k * dt_s, config)
    times = k + stride * np.arange(-history, future + 1)
    inside = (times >= 0) & (times < states.shape[1])
    clipped = np.clip(times, 0, states.shape[1] - 1)
    return Scene(states[agents][:, clipped], valid[agents][:, clipped] & inside, traffic.sizes[agents],
                 traffic.kinds[agents], ego_index=0, current_index=history, dt=dt_s * stride, lanes=lanes,
                 source=source, time_s=k * dt_s, route_xy=route)



@dataclass
class RecordedWorld:
    """One drive of a recorded scene (`SceneWorld`); `run` is its `AttackWorld`."""

    run: AttackWorld
    driver: object
    loop: object
    hooks: object
    record_: SceneRecord
    log: HumanLog
    traffic: RecordedTraffic
    planner: object            # the planner asked for: its route rule cuts the windows
    planner_spec: str
    _arrays: tuple | None = None

    def record(self, loop_record) -> dict:
        from riskmap.sim.records.record import EpisodeRecord

        world, scene = self.run, self.record_.scene
        return EpisodeRecord.measured(
            self.planner_spec, world.contact is not None, world.off_network, round(world.time_s - world.start, 3),
            loop_record.distance_m, loop_record.speeds, loop_record.gaps, loop_record.plan_times_s,
            extra={"recording": self.traffic.name, "ego_id": int(scene.ego_id), "start_s": round(world.start, 3),
                   "contact": world.contact, "driver": type(self.driver).__name__},
            **loop_record.implausible.fields()).as_dict()

    def _drove(self) -> tuple[np.ndarray, np.ndarray]:
        # The log up to the end of the drive, the ego's closed-loop states from t0 on.
        if self._arrays is None:
            log, ego = self.log, self.log.ego_id
            _, driven = self.run.driven()
            k0, end = self.record_.t0_step, self.record_.t0_step + len(driven) + 1
            states, valid = log.states[:, :end].copy(), log.valid[:, :end].copy()
            states[ego, k0 + 1:end] = driven
            valid[ego, k0:end] = True
            self._arrays = (states, valid)
        return self._arrays

    def tracks(self) -> tuple[Tracks, int]:
        states, valid = self._drove()
        return (Tracks(states, valid, self.log.sizes.copy(), self.log.kinds.copy(),
                       np.arange(len(self.log.sizes), dtype=np.int64)), self.log.ego_id)

    def final_scene(self) -> Scene:
        states, valid = self._drove()
        return _final_scene(self.traffic, states, valid, self.log.ego_id, self.log.dt_s, self.record_.scene.env_id)

    def window(self, step: int) -> Scene:
        from riskmap.sim.worlds.commonroad_replay import route_scene_config

        states, valid = self._drove()
        return _scene_at(self.traffic, states, valid, self.log.ego_id, self.log.dt_s, self.record_.scene.env_id,
                         step, round(HISTORY_S / WINDOW_DT_S), self.record_.scene.future_steps,
                         round(WINDOW_DT_S / self.log.dt_s), route_scene_config(self.planner))


@dataclass(frozen=True)
class RecordedSource:
    limits = CAR_LIMITS        # recorded cars, not highway-env's kinematic model

    def record(self, scene: AttackScene, family: str | None = None) -> SceneRecord:
        # cut from the recording again, exactly as the sweep cut it
        if not Path(scene.recording).is_file():
            raise InputError(f"recording {scene.recording} is not there; put it back (the scene was cut from it)")
        return record_recorded_scene(scene, family=family)

    def world(self, record: SceneRecord, log: HumanLog, planner, planner_spec: str, control_hz: int,
              replan_hz: int) -> RecordedWorld:
        from riskmap.sim.loop.rollout import DriveHooks, LoopConfig
        from riskmap.sim.worlds.commonroad_replay import route_scene_config

        scene = record.scene
        if abs(log.dt_s * control_hz - 1.0) > 1e-9:
            raise InputError(f"control_hz={control_hz} differs from the record's {1 / log.dt_s:g} Hz")
        traffic = log_traffic(recording_traffic(scene.recording), log)
        ego = log.ego_id
        if traffic.index_of(scene.ego_id) != ego:
            raise InputError(f"{scene.recording} no longer matches scene {scene.where}; record the scenes again")
        driver = _driver(planner, traffic, scene.ego_id)
        config = ReplayConfig(control_hz=control_hz, replan_hz=replan_hz, history_s=HISTORY_S)
        world = AttackWorld(traffic, scene.ego_id, scene.t0_s, scene.horizon_s, config, route_scene_config(driver),
                            replay_track=log.states[ego] if isinstance(driver, _LogPlayback) else None)
        loop = LoopConfig(world.n_steps, control_hz // replan_hz, HISTORY_S, config.gap_radius_m)
        return RecordedWorld(world, driver, loop, DriveHooks(), record, log, traffic, planner, planner_spec)

    def handover_step(self, record: SceneRecord) -> int:
        return record.t0_step             # the human's record up to t0, the planner's drive after


RECORDED_SOURCE = RecordedSource()
