"""`riskmap evaluate --commonroad DIR [--mode log|reactive]`: planners drive recorded human vehicles.

Every vehicle that `riskmap collect --from-commonroad` makes a demonstrator (2 s of history and
6 s of future in its record; once, however many files of its traffic configuration hold it) is
one episode: it is handed over to the planner 2 s into its
record and driven to the end of it, among the other recorded vehicles replaying their tracks
(`riskmap.sim.commonroad_replay`, a highway-env road built from the lanelets): by time in `log`
mode, along their paths braking for the ego in `reactive` mode. Per planner and
episode OUT/episodes/<planner>/<scenario>_<vehicle>.json (atomic; `--resume` skips finished
ones), then OUT/results.json and OUT/table.md with means and 90th percentiles. The table names
each planner by its display name (`riskmap.registry.display_names`), results.json by its SPEC and
that name; the episode folders keep the SPEC's (`riskmap.evaluation.evaluate.planner_slug`).

`replay` is the recording itself, tracked by the same controller: the harness's error floor.
`idm` is the rule-based baseline: IDM + MOBIL along the recorded vehicle's lanelets
(`riskmap.sim.recorded_idm`).
Safety % is the simulated scenes' (`riskmap.sim.metrics`: share of encounters with a recorded vehicle
within 30 m that are dangerously close; the planner paper's name for a danger rate, lower is
better), per episode, then mean and 90th percentile; the share of episodes without a collision
or leaving the road is reported beside it. Every collision is classified
(`riskmap.sim.failures`): at fault / struck from behind / side, and whether a driver reacting to
what it could see would have avoided it by braking or speeding up; "that count" are at fault
and avoidable.
Red-light violations (recordings with traffic lights: the ego's front crossing a stop line of
its lane while the light for its turn is red, amber counted as red;
`riskmap.sim.commonroad_replay`) are summed over the episodes beside the collisions, with the
recorded humans' own count over the same episodes as the reference (`human`); records written
before the count existed make it n/a.
Plans that fail the planner contract's checks (`riskmap.sim.plan_checks`; driven as made) are
summed the same way (`implausible_plans`, with the episodes that made any and the first one's
problems) in results.json, and named in a line under the table when there are any.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from rasterize.commonroad.reader import load_scenario
from rasterize.commonroad.tracks import RecordedTraffic
from rasterize.errors import InputError
from rasterize.timebase import REPLAN_HZ
from riskmap.data.collect_commonroad import (
    CommonRoadCollectConfig,
    no_demonstrators_message,
    scenario_files,
    unique_demonstrators,
)
from riskmap.evaluation.evaluate import planner_slug
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.parallel import run_parallel
from riskmap.infra.rundir import claim_out_dir
from riskmap.registry import display_names
from riskmap.sim.failures import summarise_failures
from riskmap.sim.plan_checks import implausible_note, summarise_implausible
from riskmap.sim.record import current_names

METRICS = ("safety_pct", "ade_m", "goal_error_m", "distance_m", "human_distance_m", "min_gap_m")
GAP_CAP_M = 1e3       # a min gap of None (nobody within the gap radius) counts as this far


_TRAFFIC: dict = {}


def _traffic(path: Path) -> RecordedTraffic:
    """This process's parsed recording of `path` (parsing a file takes about a second)."""
    if path not in _TRAFFIC:
        _TRAFFIC[path] = RecordedTraffic(load_scenario(path), path.stem)
    return _TRAFFIC[path]


def _planner(spec: str, traffic: RecordedTraffic, vehicle_id: int, seed: int,
             goal_variance: float | None = None):
    """The planner for one episode. `replay` and `idm` are tied to their recording; any other SPEC
    is made once per process and reused (each episode resets it, so results do not depend on order)."""
    from riskmap.registry import cached_planner
    from riskmap.sim.commonroad_replay import RecordedFuturePlanner
    from riskmap.sim.recorded_idm import RecordedRouteIdmPlanner

    if spec == "replay":
        return RecordedFuturePlanner(traffic, vehicle_id)
    if spec == "idm":
        return RecordedRouteIdmPlanner(traffic, vehicle_id)
    return cached_planner(spec, seed, goal_variance)


def _episode_path(out: Path, spec: str, scenario: str, vehicle: int) -> Path:
    return out / "episodes" / planner_slug(spec) / f"{scenario}_{vehicle}.json"


def _run_episode(task: tuple) -> dict:
    """Drive one (planner, recording, vehicle) episode and write its record; a worker's job."""
    import torch

    from riskmap.sim.commonroad_replay import ReplayConfig, replay_commonroad_episode

    torch.set_num_threads(1)          # workers run side by side
    spec, path, vehicle, seed, goal, mode, goal_variance, replan_hz, out = task
    traffic = _traffic(path)
    planner = _planner(spec, traffic, vehicle, seed, goal_variance)
    result = replay_commonroad_episode(traffic, vehicle, planner,
                                       config=ReplayConfig(goal=goal, mode=mode, replan_hz=replan_hz))
    write_json(_episode_path(out, spec, traffic.name, vehicle), result)
    return result


def summarise(records: list[dict]) -> dict:
    def stats(key):
        values = np.array([GAP_CAP_M if r[key] is None else min(r[key], GAP_CAP_M) for r in records],
                          dtype=float)
        return {"mean": float(values.mean()), "p90": float(np.percentile(values, 90))}

    def total(key):
        values = [r.get(key) for r in records]
        return None if any(v is None for v in values) else int(sum(values))

    classes = summarise_failures([r["collision"].get("failure") for r in records if r["collision"]], len(records))
    return {"episodes": len(records),
            "safe_episodes_pct": 100.0 * float(np.mean([not (r["collided"] or r["off_road"])
                                                        for r in records])),
            # Summed over the episodes; None when a record predates the count.
            "red_light_violations": total("red_light_violations"),
            "human_red_light_violations": total("human_red_light_violations"),
            "red_light_violation_episodes": (None if total("red_light_violations") is None else
                                             int(sum(r["red_light_violations"] > 0 for r in records))),
            "collision_rate": float(np.mean([r["collided"] for r in records])),
            # A log-replayed vehicle cannot see the ego: hit from behind is the replay's doing,
            # driving into a vehicle ahead the planner's (at fault). The classes of every
            # collision (riskmap.sim.failures); a record written before them is "unknown".
            **{k: classes[k] for k in ("at_fault", "struck_from_behind", "side", "avoidable", "counted",
                                       "unknown")},
            "off_road_rate": float(np.mean([r["off_road"] for r in records])),
            **summarise_implausible(records, lambda r: f"on {r['scenario']} vehicle {r['ego_id']}"),
            **{key: stats(key) for key in METRICS}}


def _count(value) -> str:
    return "n/a" if value is None else str(value)


def markdown_table(results: dict) -> str:
    """The table of `results` ({SPEC: summary}), a row per planner under its display name."""
    names = display_names(results)
    lines = [("| planner | episodes | Safety % (danger) | safe episodes % | collisions (that count: at fault and "
              "avoidable; at fault / struck from behind / side) | red-light violations (human) | off-road | ADE (m) | "
              "goal error (m) | driven (m) | human (m) |"),
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for spec, s in results.items():
        lines.append(
            f"| {names[spec]} | {s['episodes']} | {s['safety_pct']['mean']:.1f} / {s['safety_pct']['p90']:.1f} | "
            f"{s['safe_episodes_pct']:.0f} | "
            f"{100 * s['collision_rate']:.0f}% ({_count(s.get('counted'))}; {s['at_fault']} / "
            f"{s['struck_from_behind']} / {_count(s.get('side'))}"
            f"{'; ' + str(s['unknown']) + ' unknown' if s.get('unknown') else ''}) | "
            f"{_count(s.get('red_light_violations'))} ({_count(s.get('human_red_light_violations'))}) | "
            f"{100 * s['off_road_rate']:.0f}% | {s['ade_m']['mean']:.2f} / {s['ade_m']['p90']:.2f} | "
            f"{s['goal_error_m']['mean']:.2f} / {s['goal_error_m']['p90']:.2f} | "
            f"{s['distance_m']['mean']:.1f} | {s['human_distance_m']['mean']:.1f} |")
    note = implausible_note({names[spec]: (s, s["episodes"]) for spec, s in results.items()})
    return "\n".join(lines) + "\n" + ("\n" + note if note else "")


def evaluate_commonroad(recordings: list[str | Path], planners: tuple[str, ...], out: Path,
                        seed: int = 0, resume: bool = False, progress: bool = True,
                        workers: int = 1, goal: str = "route", mode: str = "log",
                        goal_variance: float | None = None, replan_hz: int = REPLAN_HZ,
                        limit: int | None = None) -> dict:
    """Run every planner on every recorded demonstrator (episodes on `workers` processes) towards
    `goal` among others replayed in `mode` (riskmap.sim.commonroad_replay.ReplayConfig: route or
    human; log or reactive); `goal_variance` (cells²) overrides risk-map planners' planning-time
    goal variance; `replan_hz`: how often planners replan (a divisor of the 10 Hz control rate);
    `limit`: only that many recorded vehicles, drawn with `seed` (kept in file order), the same
    ones for every planner. Returns {planner: summary}."""
    from tqdm import tqdm

    from riskmap.sim.commonroad_replay import ReplayConfig

    out = Path(out)
    ReplayConfig(goal=goal, mode=mode, replan_hz=replan_hz)    # validates them before any work
    files = scenario_files(recordings, flag="--commonroad")
    # The recording as it is (no smoothing); a vehicle recorded in several files of one traffic
    # configuration is one episode (the first file's).
    config = CommonRoadCollectConfig(files=(), smoothing_s=0.0)
    demos, traffics, skipped = unique_demonstrators(files, config)
    if not demos:
        raise InputError(f"--commonroad: {no_demonstrators_message(files, config, skipped)}; "
                         "nothing to evaluate")
    _TRAFFIC.update(traffics)
    episodes = [(d.path, traffics[d.path].name, int(traffics[d.path].ids[d.agent])) for d in demos]
    if limit is not None:
        if limit < 1:
            raise InputError(f"--max-episodes {limit}: give at least 1 recorded vehicle")
        if limit < len(episodes):
            keep = np.sort(np.random.default_rng(seed).choice(len(episodes), limit, replace=False))
            episodes = [episodes[i] for i in keep]
    names = display_names(planners)       # a bad or repeated name= fails here too
    for spec in planners:           # a bad SPEC fails here, before anything is written
        if spec not in ("replay", "idm"):       # these two are made per recorded vehicle
            _planner(spec, None, 0, seed, goal_variance)
    meta = {"recordings": [str(p) for p in files], "planners": list(planners), "seed": seed, "goal": goal,
            "mode": mode, **({"goal_variance": goal_variance} if goal_variance is not None else {}),
            **({"max_episodes": limit} if limit is not None else {}),
            # named only when not the default, so run.json of runs from before it still resume
            **({"replan_hz": replan_hz} if replan_hz != ReplayConfig.replan_hz else {})}
    # Records are per planner and episode, so a resumed run may name more (or fewer) planners:
    # the new ones' episodes are driven, the table covers the planners named now.
    claim_out_dir(out, holds="an evaluation", marker="run.json", resume=resume, settings_file="run.json",
                  settings=meta, may_change=("planners",))
    todo = [(spec, path, vehicle, seed, goal, mode, goal_variance, replan_hz, out) for spec in planners for path, name, vehicle in episodes
            if not (resume and _episode_path(out, spec, name, vehicle).exists())]
    bar = tqdm(total=len(todo), disable=not progress, desc="evaluate recordings")
    for _ in run_parallel(_run_episode, todo, workers):
        bar.update()
    bar.close()
    records = {spec: [current_names(json.loads(_episode_path(out, spec, name, vehicle).read_text()))
                      for _, name, vehicle in episodes] for spec in planners}
    results = {spec: {"name": names[spec], **summarise(rs)} for spec, rs in records.items()}
    write_json(out / "results.json", {**meta, "results": results})
    atomic_write(out / "table.md", lambda f: f.write(markdown_table(results).encode()))
    return results
