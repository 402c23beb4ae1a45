"""A stored attack scene's kind as a source: what builds the world its rollout drives.

`adversary.crash.judge.rollout` drives every scene one way: it splices the generated tracks into
the scene's log, asks the scene's source for the world (`SceneSource.world`), runs the one closed
loop (`riskmap.sim.loop.rollout.drive_world`) on it and reads the drive back from that world. What
differs between the kinds lives in their source:

- `HighwaySource` (adversary.crash.highway_source): highway-env scenes. `LogReplayEpisode`
  replays the spliced log; the planner takes the ego at t = 0 and drives the whole log; the
  drive's record is `riskmap.sim.worlds.highway_drive.drive_episode`'s.
- `RecordedSource` (adversary.crash.recorded_source): scenes cut from CommonRoad recordings. The
  CommonRoad world replays the spliced log on the recording's lanelets; the ego is the human's
  record up to t0 and handed over there; the record names the planner by its SPEC.

This is riskmap's scenario-source idea (riskmap.evaluation.sources) for attack scenes: the kind
of scene, not a flag tested by the judge, decides how it is driven. Sources hold no state (one
per kind), so workers may build them anywhere; a `SceneWorld` serves one drive.
"""

from __future__ import annotations

from typing import Protocol

from adversary.crash.scenes import AttackScene, SceneRecord
from rasterize.tracks import Tracks
from riskmap.sim.worlds.log_replay import HumanLog


class SceneWorld(Protocol):
    """One drive of a scene: the world, what drives its ego, and how; then what it recorded."""

    run: object            # the riskmap.sim.loop.world.World that drive_world steps
    driver: object         # what drives the ego there: the planner, or what stands in for it
    loop: object           # riskmap.sim.loop.rollout.LoopConfig
    hooks: object          # riskmap.sim.loop.rollout.DriveHooks

    def record(self, loop_record) -> dict:
        """The drive's record (`Rollout.drive`) from drive_world's `LoopRecord`."""

    def tracks(self) -> tuple[Tracks, int]:
        """(tracks with ids: the log agent each row replays, ego) as `Rollout` holds them."""

    def final_scene(self):
        """The last step with the whole drive as history, at the control rate (`keep_scene`)."""

    def window(self, step: int):
        """The training window cut at 10 Hz step `step` (`rollout`'s scene_steps)."""


class SceneSource(Protocol):
    limits: object         # riskmap.sim.records.failures limits the failure classifier holds the ego to

    def record(self, scene: AttackScene, family: str | None = None) -> SceneRecord:
        """Record `scene` (the human's drive up to and past t0, the others around it); InputError
        when it cannot be attacked. `family`: a recording's traffic-model family (default: from
        its file name); highway-env scenes have their env's."""

    def world(self, record: SceneRecord, log: HumanLog, planner, planner_spec: str, control_hz: int,
              replan_hz: int) -> SceneWorld:
        """The world in which `planner` drives against `log` (the scene's spliced log)."""

    def handover_step(self, record: SceneRecord) -> int:
        """The log step at which the planner takes the ego over (before it the ego is the human's
        record): what a drive is measured from (`adversary.crash.evaluate_source`)."""


def scene_source(scene: AttackScene) -> SceneSource:
    """The source of `scene`'s kind: a scene cut from a recording names it (`scene.recording`)."""
    if scene.recording:
        from adversary.crash.recorded_source import RECORDED_SOURCE

        return RECORDED_SOURCE
    from adversary.crash.highway_source import HIGHWAY_SOURCE

    return HIGHWAY_SOURCE
