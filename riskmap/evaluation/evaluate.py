"""`riskmap evaluate`: the planner benchmark (planner paper Table I) in closed loop.

For every episode e of (env, seed) the IDM/MOBIL human is driven first and recorded
(OUT/logs/episode_NNNNNN.npz). Then every planner drives the ego of that same episode from the
human's start, along the human's route:

    mode log        the other vehicles replay the human's record with synchronised time
                    (`riskmap.sim.log_replay`); the episode lasts as long as the record
    mode reactive   the other vehicles are the simulator's IDM/MOBIL drivers and react

`idm` (Human) is the record itself, so its ADE and goal error are 0 by construction; `replay`
plays the record back through the harness (log mode only). Metrics per episode
(`riskmap.sim.metrics`) go to OUT/episodes/<planner>/episode_NNNNNN.json as each finishes; at the end
OUT/episodes.csv (one row per planner and episode), OUT/results.json (mean and 90th percentile
over episodes) and OUT/table.md. `--resume` skips every file already written. The table shows
each planner by its display name (`riskmap.registry.display_names`); the CSV and results.json
carry the whole SPEC beside it, and the episode folders stay named by the SPEC (`planner_slug`).
Plans that fail the planner contract's checks (`riskmap.sim.plan_checks`; driven as made) are
counted per episode (`implausible_plans`, with the first one's problems) and per planner in
results.json; the table gets a line under it naming the planners that made any.
"""

from __future__ import annotations

import csv
import json
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from rasterize.config import family_of_env
from rasterize.errors import InputError
from rasterize.timebase import CONTROL_HZ, REPLAN_HZ
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.parallel import run_parallel
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import claim_out_dir
from riskmap.registry import cached_planner, display_name, display_names
from riskmap.sim.episode import FAMILY_SETUPS, cached_env
from riskmap.sim.failures import summarise_failures
from riskmap.sim.metrics import (
    SafetyConfig,
    ade_m,
    dangerous_encounters,
    goal_error_m,
    mean_jerk_mps3,
    path_length_m,
    safety_pct,
    summarise_metric,
)
from riskmap.sim.plan_checks import implausible_note, summarise_implausible
from riskmap.sim.record import EpisodeRecord, current_names
from riskmap.sim.rollout import check_replan_hz

MODES = ("log", "reactive")
# Per-episode values summarised as mean and 90th percentile over episodes.
METRICS = ("safety_pct", "ade_m", "goal_error_m", "distance_m", "jerk_mps3", "plan_ms_mean")
RATES = ("collided", "off_road")
CSV_FIELDS = ("planner", "name", "label", "episode", "mode", "collided", "off_road", "safety_pct", "dangerous",
              "encounters", "ade_m", "goal_error_m", "distance_m", "jerk_mps3", "simulated_s",
              "plan_ms_mean", "plan_ms_p90", "plan_calls", "implausible_plans")


@dataclass(frozen=True)
class EvalConfig:
    """One benchmark run. Times in seconds, rates in Hz."""

    env_id: str
    planners: tuple[str, ...]
    episodes: int
    seed: int = 0
    mode: str = "log"
    control_hz: int = CONTROL_HZ
    replan_hz: int = REPLAN_HZ
    episode_s: float | None = None        # default: the family's episode length
    safety: SafetyConfig = field(default_factory=SafetyConfig)

    def __post_init__(self) -> None:
        family = family_of_env(self.env_id)
        if self.mode not in MODES:
            raise InputError(f"--mode {self.mode!r} is unknown; use log or reactive")
        if self.episodes < 1:
            raise InputError("--episodes must be at least 1")
        if not self.planners or len(set(self.planners)) != len(self.planners):
            raise InputError(f"--planners {','.join(self.planners)!r}: give each planner SPEC once")
        display_names(self.planners)      # a bad or repeated name= fails before any work
        if self.mode == "reactive" and "replay" in self.planners:
            raise InputError("planner `replay` plays back the record, which reactive traffic no longer "
                             "follows; use it with --mode log only")
        check_replan_hz(self.replan_hz, self.control_hz)
        if self.episode_s is None:
            object.__setattr__(self, "episode_s", FAMILY_SETUPS[family].episode_s)
        if not 0 < self.episode_s < float("inf"):
            raise InputError(f"--episode-s must be positive seconds, got {self.episode_s}")


def planner_label(spec: str) -> str:
    """The Table I name of a planner SPEC (the paper's row names; other planners: their
    display name)."""
    kind = spec.partition(":")[0].replace("-", "_")
    return {"idm": "Human", "replay": "Replay", "cv": "CV", "riskmap": "Risk-aware (ours)",
            "cnn": "CNN", "cnn_lstm": "CNN-LSTM", "rvsg": "RvS-G"}.get(kind) or display_name(spec)


def planner_slug(spec: str) -> str:
    """The folder of a planner's episode records, made from the whole SPEC, not its display
    name: `--resume` finds finished episodes by it, and a display name depends on the other
    planners of the run (`-2` suffixes) and on `name=`, so adding a planner or renaming one on
    resume could hand one planner's records to another. Folders of earlier runs keep resuming."""
    return re.sub(r"[^A-Za-z0-9]+", "_", spec).strip("_")


def _log_path(out: Path, episode: int) -> Path:
    return out / "logs" / f"episode_{episode:06d}.npz"


def _result_path(out: Path, spec: str, episode: int) -> Path:
    return out / "episodes" / planner_slug(spec) / f"episode_{episode:06d}.json"


def trajectory_metrics(states: np.ndarray, valid: np.ndarray, sizes: np.ndarray, ego_id: int,
                       dt_s: float, human_xy: np.ndarray, safety: SafetyConfig) -> dict:
    """Metrics of one driven episode from its record (states [A, S, 6], valid [A, S], sizes [A, 2])."""
    ego = states[ego_id][valid[ego_id]]
    others = np.delete(np.arange(states.shape[0]), ego_id)
    dangerous, encounters = dangerous_encounters(ego, sizes[ego_id], states[others], valid[others],
                                                 sizes[others], safety)
    return {"ade_m": ade_m(ego[:, :2], human_xy), "goal_error_m": goal_error_m(ego[:, :2], human_xy),
            "distance_m": path_length_m(ego[:, :2]), "jerk_mps3": mean_jerk_mps3(ego[:, :2], dt_s),
            "dangerous": dangerous, "encounters": encounters,
            "safety_pct": safety_pct(dangerous, encounters),
            "simulated_s": round((len(ego) - 1) * dt_s, 3)}


def _planner(spec: str, seed: int):
    """This process's planner for `spec` (one torch thread: workers run side by side)."""
    import torch

    torch.set_num_threads(1)
    return cached_planner(spec, seed)


def _record_task(args: tuple) -> None:
    record_task(*args)


def _planner_task(args: tuple) -> tuple[str, int, dict]:
    return _run_planner_task(*args)


def record_task(config: EvalConfig, out: Path, episode: int) -> None:
    """Record the human's episode unless it is on disk."""
    from riskmap.sim.log_replay import record_human_episode

    path = _log_path(out, episode)
    if path.exists():
        return
    log = record_human_episode(cached_env(config.env_id, config.control_hz), config.env_id, config.seed,
                               episode, config.control_hz, config.episode_s)
    log.save(path)


def _table_record(spec: str, base: dict, metrics: dict, collided: bool, off_road: bool,
                  drive: dict | None) -> dict:
    """One Table I row as an `EpisodeRecord` dict. Distance and simulated time are the recorded
    states' (the same for the human's log and a driven episode); speed, gap and plan times come
    from the drive (`drive_episode`'s record) and are None for the human, who is not driven."""
    metrics = dict(metrics)
    drive = drive or {"mean_speed_mps": None, "min_gap_m": None, "plan_calls": 0,
                      "plan_ms_median": None, "plan_ms_mean": None, "plan_ms_p90": None,
                      "implausible_plans": 0, "implausible_plan_first": None}
    return EpisodeRecord(
        planner=spec, collided=bool(collided), off_road=bool(off_road),
        simulated_s=metrics.pop("simulated_s"), distance_m=metrics.pop("distance_m"),
        mean_speed_mps=drive["mean_speed_mps"], min_gap_m=drive["min_gap_m"],
        plan_calls=drive["plan_calls"], plan_ms_median=drive["plan_ms_median"],
        plan_ms_mean=drive["plan_ms_mean"], plan_ms_p90=drive["plan_ms_p90"],
        implausible_plans=drive["implausible_plans"], implausible_plan_first=drive["implausible_plan_first"],
        extra={**base, **metrics}).as_dict()


def planner_task(config: EvalConfig, out: Path, spec: str, episode: int) -> dict:
    """Drive (or, for `idm`, read) one episode; returns its record of metrics."""
    from riskmap.sim.episode import Episode
    from riskmap.sim.log_replay import HumanLog, LogReplayEpisode
    from riskmap.sim.plan import traits_of
    from riskmap.sim.rollout import DriveConfig, drive_episode

    from riskmap.sim.failures import classify_failure, classify_run, first_contact

    log = HumanLog.load(_log_path(out, episode))
    human_xy = log.ego_xy()
    base = {"label": planner_label(spec), "episode": episode, "mode": config.mode}
    if spec == "idm":
        metrics = trajectory_metrics(log.states, log.valid, log.sizes, log.ego_id, log.dt_s, human_xy,
                                     config.safety)
        contact = first_contact(log.states, log.valid, log.sizes, log.ego_id) if log.crashed else None
        base["failure"] = None if contact is None else classify_failure(
            log.states, log.valid, log.sizes, log.ego_id, contact[1], contact[0], log.dt_s)
        return _table_record(spec, base, metrics, log.crashed, log.off_road, None)
    env = cached_env(config.env_id, config.control_hz)
    planner = _planner(spec, config.seed)
    traits = traits_of(planner)
    replay = bool(traits.requires_log)
    if replay:
        traits.set_log(log)
    if config.mode == "log":
        run = LogReplayEpisode(env, config.env_id, config.seed, episode, log, config.control_hz,
                               replay_ego=replay)
    else:
        run = Episode(env, config.env_id, config.seed, episode, config.control_hz)
    drive_config = DriveConfig(config.env_id, config.episodes, config.seed, config.control_hz,
                               config.replan_hz, config.episode_s)
    record = drive_episode(env, planner, drive_config, episode, run=run)
    states, valid, sizes, _ = run.recorder.arrays()
    metrics = trajectory_metrics(states, valid, sizes, run.recorder.ego_id, run.dt, human_xy,
                                 config.safety)
    base["failure"] = classify_run(run) if record["collided"] else None
    return _table_record(spec, base, metrics, record["collided"], record["off_road"], record)


def _run_planner_task(config: EvalConfig, out: Path, spec: str, episode: int) -> tuple[str, int, dict]:
    record = planner_task(config, out, spec, episode)
    write_json(_result_path(out, spec, episode), record)
    return spec, episode, record


def summarise(config: EvalConfig, records: list[dict]) -> dict:
    """Per planner: mean and 90th percentile over episodes, rates, pooled Safety %."""
    table = {}
    names = display_names(config.planners)
    for spec in config.planners:
        rows = [r for r in records if r["planner"] == spec]
        if not rows:
            continue
        entry = {"name": names[spec], "label": planner_label(spec), "episodes": len(rows)}
        for key in METRICS:
            entry[key] = summarise_metric([r[key] for r in rows])
        for key in RATES:
            entry[f"{key}_rate"] = float(np.mean([bool(r[key]) for r in rows]))
        collided = [r for r in rows if r["collided"]]
        # every collision classified (riskmap.sim.failures); a record without it is unknown
        entry["failures"] = summarise_failures([r.get("failure") for r in collided], len(rows))
        dangerous = sum(r["dangerous"] for r in rows)
        encounters = sum(r["encounters"] for r in rows)
        entry["safety_pct_pooled"] = safety_pct(dangerous, encounters)
        entry["encounters"] = encounters
        entry.update(summarise_implausible(rows, lambda r: f"in episode {r['episode']}"))
        table[spec] = entry
    return table


def _fmt(value, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _counted(entry: dict) -> str:
    """The collisions that count (valid, avoidable, at fault), "?" with unknown ones beside."""
    f = entry.get("failures")
    if not f:
        return "?"
    return f"{f['counted']}" + (f", {f['unknown']} unknown" if f["unknown"] else "")


def markdown_table(config: EvalConfig, table: dict) -> str:
    lines = [(f"{config.env_id}, mode {config.mode}, seed {config.seed}: mean / 90th percentile over "
             "episodes"), "",
             ("| planner | episodes | Safety % (danger) | ADE (m) | Goal (m) | collisions (that count) | off-road | "
             "progress (m) | jerk (m/s³) | plan ms/call |"),
             "|---|---|---|---|---|---|---|---|---|---|"]
    for entry in table.values():
        def pair(key, digits=2, entry=entry):
            return f"{_fmt(entry[key]['mean'], digits)} / {_fmt(entry[key]['p90'], digits)}"

        lines.append(
            f"| {entry['name']} | {entry['episodes']} | {pair('safety_pct', 1)} | {pair('ade_m')} | "
            f"{pair('goal_error_m')} | {100 * entry['collided_rate']:.0f}% ({_counted(entry)}) | "
            f"{100 * entry['off_road_rate']:.0f}% | {pair('distance_m', 0)} | {pair('jerk_mps3')} | "
            f"{pair('plan_ms_mean', 1)} |")
    note = implausible_note({entry["name"]: (entry, entry["episodes"]) for entry in table.values()})
    return "\n".join(lines) + "\n" + ("\n" + note if note else "")


def _check_out(config: EvalConfig, out: Path, resume: bool) -> dict:
    # More episodes or planners may be added on resume; nothing else may change.
    settings = {"config": asdict(config)}
    claim_out_dir(out, holds="an evaluation", marker="run.json", resume=resume, settings_file="run.json",
                  settings=settings, may_change=("config.episodes", "config.planners"),
                  differs="other settings (only --episodes and --planners may change)")
    return {**settings, **provenance()}


def evaluate(config: EvalConfig, out: Path, workers: int = 1, resume: bool = False,
             progress: bool = True) -> dict:
    """Run (or finish) the benchmark; returns results.json's content."""
    from tqdm import tqdm

    out = Path(out)
    for spec in config.planners:   # fail on a bad SPEC before any work starts
        if spec != "idm":
            _planner(spec, config.seed)
    meta = _check_out(config, out, resume)
    todo_logs = [e for e in range(config.episodes) if not _log_path(out, e).exists()]
    todo = [(s, e) for e in range(config.episodes) for s in config.planners
            if not _result_path(out, s, e).exists()]
    bar = tqdm(total=len(todo_logs) + len(todo), disable=not progress, desc=f"evaluate {config.env_id}")
    # Every human episode is recorded before any planner drives it (planners replay the record).
    for _ in run_parallel(_record_task, [(config, out, e) for e in todo_logs], workers):
        bar.update()
    for _ in run_parallel(_planner_task, [(config, out, s, e) for s, e in todo], workers):
        bar.update()
    bar.close()
    names = display_names(config.planners)      # this run's names, whatever earlier runs used
    records = [{**current_names(json.loads(_result_path(out, s, e).read_text())), "name": names[s]}
               for s in config.planners for e in range(config.episodes)]
    atomic_write(out / "episodes.csv", lambda f: f.write(_csv_text(list(CSV_FIELDS), records).encode()))
    table = summarise(config, records)
    results = {**meta, "planners": table}
    write_json(out / "results.json", results)
    atomic_write(out / "table.md", lambda f: f.write(markdown_table(config, table).encode()))
    return results


def _csv_text(fields: list[str], records: list[dict]) -> str:
    import io

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fields, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(records)
    return buffer.getvalue()
