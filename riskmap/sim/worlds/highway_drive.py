"""Driving the ego through highway-env episodes: `DriveConfig` (an env, its seeds, the rates)
and `drive_episode`, one seeded `Episode` driven by the one loop (`riskmap.sim.loop.rollout.drive_world`)
and reported as the one episode record."""

from __future__ import annotations

from dataclasses import dataclass

from rasterize.config import family_of_env
from rasterize.timebase import CONTROL_HZ, HISTORY_S, REPLAN_HZ
from riskmap.sim.loop.plan import traits_of
from riskmap.sim.loop.rollout import DriveHooks, LoopConfig, LoopRecord, check_replan_hz, drive_world
from riskmap.sim.records.record import EpisodeRecord
from riskmap.sim.worlds.episode import FAMILY_SETUPS, Episode


@dataclass(frozen=True)
class DriveConfig:
    env_id: str
    episodes: int
    seed: int = 0
    control_hz: int = CONTROL_HZ
    replan_hz: int = REPLAN_HZ
    episode_s: float | None = None     # default: the family's episode length
    gap_radius_m: float = 40.0         # others farther than this do not count for the min gap
    history_s: float = HISTORY_S

    def __post_init__(self) -> None:
        family = family_of_env(self.env_id)
        if self.episode_s is None:
            object.__setattr__(self, "episode_s", FAMILY_SETUPS[family].episode_s)
        check_replan_hz(self.replan_hz, self.control_hz)

    def loop(self) -> LoopConfig:
        """How `drive_world` drives one of these episodes: episode_s at the control rate."""
        return LoopConfig(round(self.episode_s * self.control_hz), self.control_hz // self.replan_hz,
                          self.history_s, self.gap_radius_m)


def drive_episode(env, planner, config: DriveConfig, episode: int, hooks: DriveHooks = DriveHooks(),
                  run: Episode | None = None) -> dict:
    """Drive one closed-loop episode; `hooks` perturb or observe it (see `DriveHooks`). `run`: an
    already reset Episode to drive instead of a fresh one (for instance one whose traffic replays
    a log; `hooks.setup` is then not used); the caller can read its recorder afterwards. Returns
    the episode's `EpisodeRecord` as a dict (extras: episode, env_seed, driver)."""
    if run is None:
        run = Episode(env, config.env_id, config.seed, episode, config.control_hz,
                      setup=hooks.setup)
    return episode_record(run, planner, drive_world(run, planner, config.loop(), hooks), episode)


def episode_record(run: Episode, planner, loop_record: LoopRecord, episode: int) -> dict:
    """`drive_episode`'s record of `run` once `drive_world` drove it with `planner`: for callers
    that run the loop on an `Episode` themselves, next to worlds of other kinds."""
    record = EpisodeRecord.measured(
        traits_of(planner).name if loop_record.drives_itself else type(planner).__name__, run.crashed, run.off_network,
        round(run.time_s, 3), loop_record.distance_m, loop_record.speeds, loop_record.gaps,
        loop_record.plan_times_s, extra={"episode": episode, "env_seed": run.seed, "driver": run.driver},
        yield_events=loop_record.yield_events, **loop_record.implausible.fields())
    return record.as_dict()
