"""`riskmap evaluate`: the planner benchmark (planner paper Table I) in closed loop, on any source
of scenarios (`riskmap.evaluation.sources`: highway-env seeds with `--env`, the recorded vehicles
of CommonRoad files with `--commonroad`; stored attack scenes, unattacked, with `adversary evaluate`).

Every scenario's recorded log is made first where the source makes one (highway-env: the
IDM/MOBIL human, OUT/logs/episode_NNNNNN.npz); then every planner drives every scenario. Its
record goes to OUT/episodes/<planner>/<scenario id>.json as each finishes (atomic; `--resume`
skips every file already written); at the end, whatever the source:

    OUT/episodes.csv    one row per planner and episode, the same columns for every source
                        (empty where a column does not apply to it)
    OUT/results.json    the source's settings and, per planner SPEC (under "planners", and
                        under "results" as `evaluate --commonroad` runs wrote it), means and
                        90th percentiles over episodes, rates, collision classes, red-light and
                        implausible-plan counts
    OUT/table.md        one layout for every source; a column that does not apply to it is "–"

Safety % is the share of encounters (another vehicle within 30 m) that are dangerously close
(`riskmap.sim.records.metrics`), per episode, then mean and 90th percentile; the share of episodes
without a collision or leaving the road is reported beside it. Every collision is classified
(`riskmap.sim.records.failures`): at fault / struck from behind / side, and whether a driver reacting to
what it could see would have avoided it; "that count" are at fault and avoidable. Red-light
violations (recordings with traffic lights) are summed with the recorded humans' own count as the
reference; records written before the count existed make it n/a. Plans that fail the planner
contract's checks (`riskmap.sim.loop.plan_checks`; driven as made) are summed the same way and named in
a line under the table. The table shows each planner by its display name
(`riskmap.registry.display_names`); the CSV and results.json carry the whole SPEC beside it, and
the episode folders stay named by the SPEC (`planner_slug`).
"""

from __future__ import annotations

import csv
import io
import json
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from riskmap.evaluation.sources import OPTIONAL_COLUMNS, Scenario, ScenarioSource, planner_label
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.parallel import run_parallel
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import claim_out_dir
from riskmap.registry import display_names
from riskmap.sim.loop.plan_checks import implausible_note, summarise_implausible
from riskmap.sim.records.failures import summarise_failures
from riskmap.sim.records.metrics import safety_pct, summarise_metric
from riskmap.sim.records.record import current_names

__all__ = ["evaluate", "planner_label", "planner_slug", "summarise", "markdown_table"]

# Per-episode values summarised as mean and 90th percentile over episodes.
METRICS = ("safety_pct", "ade_m", "goal_error_m", "distance_m", "human_distance_m", "jerk_mps3", "plan_ms_mean")
RATES = ("collided", "off_road")
GAP_CAP_M = 1e3       # a min gap of None (nobody within the gap radius) counts as this far
CSV_FIELDS = ("planner", "name", "label", "episode", "mode", "collided", "off_road", "safety_pct", "dangerous",
              "encounters", "ade_m", "goal_error_m", "distance_m", "human_distance_m", "min_gap_m",
              "red_light_violations", "human_red_light_violations", "jerk_mps3", "simulated_s",
              "plan_ms_mean", "plan_ms_p90", "plan_calls", "implausible_plans",
              "no_solution_plans")
FAILURE_CLASSES = ("at_fault", "struck_from_behind", "side", "avoidable", "counted", "unknown")


def planner_slug(spec: str) -> str:
    """The folder of a planner's episode records, made from the whole SPEC, not its display
    name: `--resume` finds finished episodes by it, and a display name depends on the other
    planners of the run (`-2` suffixes) and on `name=`, so adding a planner or renaming one on
    resume could hand one planner's records to another. Folders of earlier runs keep resuming."""
    return re.sub(r"[^A-Za-z0-9]+", "_", spec).strip("_")


def _result_path(out: Path, spec: str, scenario: Scenario) -> Path:
    return Path(out) / "episodes" / planner_slug(spec) / f"{scenario.id}.json"


def prepare_task(scenario: Scenario, out: Path) -> None:
    scenario.prepare(out)


def drive_task(scenario: Scenario, spec: str, out: Path) -> dict:
    """Drive one episode and write its record; a worker's job."""
    record = scenario.drive(spec, out)
    write_json(_result_path(out, spec, scenario), record)
    return record


def _prepare(args: tuple) -> None:
    prepare_task(*args)


def _drive(args: tuple) -> None:
    drive_task(*args)


def _total(rows: list[dict], key: str) -> int | None:
    """Summed over the episodes; None when a record predates the count."""
    values = [r.get(key) for r in rows]
    return None if any(v is None for v in values) else int(sum(values))


def _min_gap(rows: list[dict]) -> dict:
    # Over driven episodes only (the highway-env human is the log, not driven: no gap measured);
    # None, nobody within the gap radius, counts as GAP_CAP_M.
    driven = [r for r in rows if r.get("mean_speed_mps") is not None]
    if not driven:
        return {"mean": None, "p90": None}
    values = np.array([GAP_CAP_M if r["min_gap_m"] is None else min(r["min_gap_m"], GAP_CAP_M)
                       for r in driven], dtype=float)
    return {"mean": float(values.mean()), "p90": float(np.percentile(values, 90))}


def summarise(source: ScenarioSource, planners: Sequence[str], rows: list[dict]) -> dict:
    """Per planner SPEC: mean and 90th percentile over episodes, rates, pooled Safety %, collision
    classes, red-light and implausible-plan counts. `rows`: the episodes in the common layout."""
    table = {}
    names = display_names(planners)
    for spec in planners:
        mine = [r for r in rows if r["planner"] == spec]
        if not mine:
            continue
        entry = {"name": names[spec], "label": mine[0].get("label") or planner_label(spec), "episodes": len(mine)}
        for key in METRICS:
            entry[key] = summarise_metric([r.get(key) for r in mine])
        entry["min_gap_m"] = _min_gap(mine)
        for key in RATES:
            entry[f"{key}_rate"] = float(np.mean([bool(r[key]) for r in mine]))
        entry["collision_rate"] = entry["collided_rate"]        # the name recording runs used
        entry["safe_episodes_pct"] = 100.0 * float(np.mean([not (r["collided"] or r["off_road"]) for r in mine]))
        # every collision classified (riskmap.sim.records.failures); a record without it is unknown
        entry["failures"] = summarise_failures([r.get("failure") for r in mine if r["collided"]], len(mine))
        entry.update({k: entry["failures"][k] for k in FAILURE_CLASSES})
        dangerous = sum(r["dangerous"] for r in mine)
        encounters = sum(r["encounters"] for r in mine)
        entry["safety_pct_pooled"] = safety_pct(dangerous, encounters)
        entry["encounters"] = encounters
        if "red_light_violations" in source.applies:
            violations = _total(mine, "red_light_violations")
            entry.update({"red_light_violations": violations,
                          "human_red_light_violations": _total(mine, "human_red_light_violations"),
                          "red_light_violation_episodes": None if violations is None else
                          int(sum(r["red_light_violations"] > 0 for r in mine))})
        entry.update(summarise_implausible(mine, source.where))
        table[spec] = entry
    return table


def _fmt(value, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _count(value) -> str:
    return "n/a" if value is None else str(value)


def _collisions(entry: dict) -> str:
    """The rate, then the collisions that count (at fault and avoidable) and the fault classes,
    "?" where the classes are missing, with unknown ones beside."""
    f = entry.get("failures")
    if not f:
        return f"{100 * entry['collided_rate']:.0f}% (?)"
    unknown = f"; {f['unknown']} unknown" if f["unknown"] else ""
    return (f"{100 * entry['collided_rate']:.0f}% ({f['counted']}; {f['at_fault']} / {f['struck_from_behind']} / "
            f"{_count(f.get('side'))}{unknown})")


def markdown_table(source: ScenarioSource, table: dict) -> str:
    """One layout for every source: a row per planner under its display name; a column that does
    not apply to the source is "–"."""
    applies = source.applies

    def pair(entry, key, digits=2):
        if key in OPTIONAL_COLUMNS and key not in applies:
            return "–"
        return f"{_fmt(entry[key]['mean'], digits)} / {_fmt(entry[key]['p90'], digits)}"

    def red_lights(entry):
        if "red_light_violations" not in applies:
            return "–"
        return f"{_count(entry['red_light_violations'])} ({_count(entry['human_red_light_violations'])})"

    lines = [f"{source.title()}: mean / 90th percentile over episodes", "",
             ("| planner | episodes | Safety % (danger) | safe episodes % | ADE (m) | Goal (m) | collisions "
              "(that count: at fault and avoidable; at fault / struck from behind / side) | red-light "
              "violations (human) | off-road | progress (m) | human (m) | jerk (m/s³) | plan ms/call |"),
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for e in table.values():
        lines.append(
            f"| {e['name']} | {e['episodes']} | {pair(e, 'safety_pct', 1)} | {e['safe_episodes_pct']:.0f} | "
            f"{pair(e, 'ade_m')} | {pair(e, 'goal_error_m')} | {_collisions(e)} | {red_lights(e)} | "
            f"{100 * e['off_road_rate']:.0f}% | {pair(e, 'distance_m', 0)} | {pair(e, 'human_distance_m', 0)} | "
            f"{pair(e, 'jerk_mps3')} | {pair(e, 'plan_ms_mean', 1)} |")
    note = implausible_note({e["name"]: (e, e["episodes"]) for e in table.values()})
    return "\n".join(lines) + "\n" + ("\n" + note if note else "")


def _csv_text(records: list[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, CSV_FIELDS, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(records)
    return buffer.getvalue()


def evaluate(source: ScenarioSource, planners: Sequence[str], out: Path, workers: int = 1,
             resume: bool = False, progress: bool = True) -> dict:
    """Run (or finish) every planner SPEC on every scenario of `source` (episodes on `workers`
    processes); returns results.json's content. A resumed run may name more planners (and, on
    highway-env, more episodes); other settings must stay."""
    from tqdm import tqdm

    out, planners = Path(out), tuple(planners)
    if not planners or len(set(planners)) != len(planners):
        raise InputError(f"--planners {','.join(planners)!r}: give each planner SPEC once")
    scenarios = source.scenarios()
    source.check(planners)            # a bad SPEC fails before anything is written
    settings = source.settings(planners)
    claim_out_dir(out, holds="an evaluation", marker="run.json", resume=resume, settings_file="run.json",
                  settings=settings, may_change=source.may_change, differs=source.differs)
    todo_logs = [s for s in scenarios if not s.prepared(out)]
    todo = [(s, spec) for s in scenarios for spec in planners if not _result_path(out, spec, s).exists()]
    bar = tqdm(total=len(todo_logs) + len(todo), disable=not progress, desc=f"evaluate {source.kind}")
    # Every log is made before any planner drives (planners are compared with it, or replay it).
    for _ in run_parallel(_prepare, [(s, out) for s in todo_logs], workers):
        bar.update()
    for _ in run_parallel(_drive, [(s, spec, out) for s, spec in todo], workers):
        bar.update()
    bar.close()
    names = display_names(planners)      # this run's names, whatever earlier runs used
    # Columns that do not apply to the source are left empty, not filled with the record's defaults.
    blank = {key: None for key in OPTIONAL_COLUMNS if key not in source.applies}
    if "red_light_violations" in blank:
        blank["human_red_light_violations"] = None
    rows = [{**s.row(spec, current_names(json.loads(_result_path(out, spec, s).read_text()))), **blank,
             "name": names[spec]} for spec in planners for s in scenarios]
    atomic_write(out / "episodes.csv", lambda f: f.write(_csv_text(rows).encode()))
    table = summarise(source, planners, rows)
    # "results": the key `evaluate --commonroad` runs wrote the same table under
    results = {**settings, **provenance(), "source": source.kind, "planners": table, "results": table}
    write_json(out / "results.json", results)
    atomic_write(out / "table.md", lambda f: f.write(markdown_table(source, table).encode()))
    return results
