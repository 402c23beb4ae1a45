"""Demonstrations from highway-env: the ego is driven by IDM + MOBIL (the "human").

Each episode: reset the env with a seed derived from (seed, episode), replace the ego by an
IDM/MOBIL vehicle with its own driver parameters (desired speed, time gap, politeness) -- at
intersections by default the `yielding` teacher, which also gives way at conflict zones by gap
acceptance (`riskmap.sim.drivers.yielding`; `--human idm` keeps plain IDM/MOBIL) -- step the
road at `record_hz`, record every vehicle, drop vehicles far from the ego (they cannot reach the
scene and they cost time), then cut training windows (history + future at `window_dt_s`) and
write them as one shard per episode (`EnvCollectSource`, collected by the one driver
`riskmap.data.collect_source.collect_source`: atomic shards, `--resume`, workers).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

from rasterize.config import FAMILY_EXTENTS, RasterConfig, family_of_env
from rasterize.errors import InputError
from rasterize.timebase import CONTROL_HZ, FUTURE_S, HISTORY_S, PLAN_DT_S

# The dataset layout and its helpers live with the one collect driver; named here too, where
# the dataset readers and older callers import them from.
from riskmap.data.collect_source import (  # noqa: F401
    FORMAT_VERSION,
    INDEX,
    MANIFEST,
    SHARD_DIR,
    collect_source,
    read_episode_info,
    shard_path,
    write_episode_shard,
    write_index_and_manifest,
)
from riskmap.sim.drivers.yielding import DEMONSTRATORS, demonstrator
from riskmap.sim.loop.rollout import LoopConfig, drive_world
from riskmap.sim.worlds.episode import FAMILY_SETUPS, Episode, FamilySetup, make_env


@dataclass(frozen=True)
class CollectConfig:
    """Everything that determines a dataset. Times in seconds, distances in metres."""

    env_id: str
    episodes: int
    seed: int = 0
    record_hz: int = CONTROL_HZ
    history_s: float = HISTORY_S
    future_s: float = FUTURE_S
    window_dt_s: float = PLAN_DT_S
    window_stride_s: float = 1.0
    crash_margin_s: float = 2.0        # drop windows whose future ends this close to an ego crash
    scene_radius_m: float = 120.0
    max_agents: int = 32
    raster: RasterConfig | None = None
    human: str | None = None           # the demonstrator's SPEC; None: the family's teacher

    def __post_init__(self) -> None:
        family = family_of_env(self.env_id)
        if self.human is None:
            object.__setattr__(self, "human", FAMILY_SETUPS[family].teacher)
        if self.human not in DEMONSTRATORS:
            raise InputError(f"--human {self.human!r} is not a demonstrator; choose one of "
                             f"{', '.join(DEMONSTRATORS)}")
        if not (isinstance(self.episodes, int) and self.episodes >= 1):
            raise InputError(f"--episodes must be a positive integer, got {self.episodes!r}")
        if self.raster is None:
            object.__setattr__(self, "raster", RasterConfig(FAMILY_EXTENTS[family]))
        stride = self.record_hz * self.window_dt_s
        if abs(stride - round(stride)) > 1e-9:
            raise InputError(f"window_dt_s={self.window_dt_s} must be a multiple of 1/record_hz")

    @property
    def family(self) -> str:
        return family_of_env(self.env_id)

    @property
    def setup(self) -> FamilySetup:
        return FAMILY_SETUPS[self.family]

    def to_dict(self) -> dict:
        data = asdict(self)
        data["family"] = self.family
        data["family_setup"] = asdict(self.setup)
        data["format_version"] = FORMAT_VERSION
        return data


def run_episode(env, config: CollectConfig, episode: int):
    """Simulate one episode with the demonstrator ego; returns (windows as Scenes, episode info)."""
    run = Episode(env, config.env_id, config.seed, episode, config.record_hz)
    drive_world(run, demonstrator(config.human), LoopConfig(round(config.setup.episode_s * config.record_hz), replan_every=1))
    recorder = run.recorder
    stride = int(round(config.window_stride_s * config.record_hz))
    first = int(round(config.history_s * config.record_hz))
    last = recorder.num_steps - 1 - int(round(config.future_s * config.record_hz))
    if run.crashed:  # a driver heading into a crash is no demonstration to learn from
        last -= int(round(config.crash_margin_s * config.record_hz))
    windows = [
        recorder.scene(step, config.history_s, config.future_s, config.window_dt_s,
                       config.scene_radius_m, config.max_agents, source=config.env_id)
        for step in range(first, last + 1, stride)
    ]
    info = {"episode": episode, "seed": run.seed, "driver": run.driver, "windows": len(windows),
            "simulated_s": run.time_s, "ego_crashed": run.crashed,
            "ego_off_network": run.off_network}
    return windows, info


@dataclass(frozen=True)
class EnvCollectSource:
    """`riskmap collect --env`'s items: episodes 0..N-1 of `config`, each driven by the
    demonstrator in this process's env (one per worker, reused across its episodes)."""

    config: CollectConfig
    unit = "episode"

    @property
    def label(self) -> str:
        return f"collect {self.config.env_id}"

    def items(self) -> range:
        return range(self.config.episodes)

    def worker_state(self):
        import cv2

        cv2.setNumThreads(1)
        return make_env(self.config.env_id, self.config.record_hz)

    def windows(self, env, episode: int) -> tuple[list, dict]:
        return run_episode(env, self.config, episode)

    def manifest_extra(self, infos: list[dict]) -> None:
        return None


def collect(config: CollectConfig, out: Path, workers: int = 1, resume: bool = False,
            progress: bool = True) -> dict:
    """Collect `config.episodes` episodes into `out`; returns the manifest."""
    return collect_source(EnvCollectSource(config), out, workers, resume, progress)
