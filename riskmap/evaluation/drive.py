"""`riskmap drive`: closed-loop episodes in highway-env with any planner driving the ego.

The traffic of episode e under seed S is exactly the traffic the demonstrations met (same env
seed, same human driver parameters); the rollout is `riskmap.sim.worlds.highway_drive.drive_episode`.
Per episode: OUT/episodes/episode_NNNNNN.json (atomic); OUT/summary.json at the end.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from riskmap.figures.panels import plan_frame_writer
from riskmap.infra.atomic import write_json
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import claim_out_dir
from riskmap.registry import display_name, make_planner
from riskmap.sim.loop.plan_checks import summarise_implausible
from riskmap.sim.loop.rollout import DriveHooks
from riskmap.sim.records.record import current_names
from riskmap.sim.worlds.episode import make_env
from riskmap.sim.worlds.highway_drive import DriveConfig, drive_episode


def mean_count(records: list[dict], key: str) -> float | None:
    """Mean of a per-episode count over the records that hold it (None if none do)."""
    values = [r[key] for r in records if r.get(key) is not None]
    return float(np.mean(values)) if values else None


def summarise(records: list[dict]) -> dict:
    def mean(key):
        # None (a min gap with nobody near, or a measure the episode lacks) is left out of the mean.
        values = [r[key] for r in records if r[key] is not None and np.isfinite(r[key])]
        return float(np.mean(values)) if values else None

    return {
        "episodes": len(records),
        "collision_rate": mean("collided"),
        "off_road_rate": mean("off_road"),
        "distance_m": mean("distance_m"),
        "mean_speed_mps": mean("mean_speed_mps"),
        "min_gap_m": mean("min_gap_m"),
        # Counts per episode; records from before a count existed hold none (left out).
        "yield_events": mean_count(records, "yield_events"),
        "red_light_violations": mean_count(records, "red_light_violations"),
        "plan_ms_median": float(np.median([r["plan_ms_median"] for r in records
                                           if r["plan_ms_median"] is not None]))
        if any(r["plan_ms_median"] is not None for r in records) else None,
        # Plans that failed the planner contract's checks (driven as made), summed.
        **summarise_implausible(records, lambda r: f"in episode {r['episode']}"),
    }


def drive(config: DriveConfig, planner_spec: str, out: Path, resume: bool = False,
          frames: bool = False, progress: bool = True, goal_variance: float | None = None) -> dict:
    from tqdm import tqdm

    out = Path(out)
    planner = make_planner(planner_spec, seed=config.seed, goal_variance=goal_variance)
    episodes_dir = out / "episodes"
    meta = {"config": asdict(config), "planner": planner_spec}
    if goal_variance is not None:
        meta["goal_variance"] = goal_variance
    claim_out_dir(out, holds="driven episodes", marker="episodes", resume=resume, settings_file="run.json",
                  settings=meta, may_change=("config.episodes",))
    meta.update(provenance())
    env = make_env(config.env_id, config.control_hz)
    records = []
    for episode in tqdm(range(config.episodes), disable=not progress, desc=f"drive {display_name(planner_spec)}"):
        path = episodes_dir / f"episode_{episode:06d}.json"
        if resume and path.exists():
            records.append(current_names(json.loads(path.read_text())))
            continue
        hooks = DriveHooks(on_plan=plan_frame_writer(
            out / "frames", planner, f"episode_{episode:06d}", f"{config.env_id} episode {episode}",
            config.env_id, name=display_name(planner_spec))
            if frames else None)
        record = drive_episode(env, planner, config, episode, hooks)
        write_json(path, record)
        records.append(record)
    summary = {**meta, "summary": summarise(records)}
    write_json(out / "summary.json", summary)
    return summary
