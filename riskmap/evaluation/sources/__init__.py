"""Scenario sources: where `riskmap evaluate`'s episodes come from.

A `ScenarioSource` yields `Scenario`s; `riskmap.evaluation.evaluate.evaluate` drives every
planner on every scenario of one source and writes one set of files whatever the source.
A scenario says:

- `id`: stable, it names the episode's record file (OUT/episodes/<planner>/<id>.json), so
  `--resume` finds finished work by it; `label`: what the CSV's `episode` column shows;
- `prepare(out)`: make the recorded log the planners are compared with, once (highway-env: drive
  the IDM/MOBIL human and save it; a recording already is its log); `recorded_log(out)` reads it;
- `drive(spec, out)`: one episode of planner SPEC, run by the existing world of the source
  (`riskmap.sim.worlds.log_replay` / `riskmap.sim.worlds.episode`, `riskmap.sim.worlds.commonroad_replay`), returned as
  the record to store; `row(spec, record)`: that record in the common per-episode layout.

The source gives the run's settings (run.json, what may change on `--resume`), the route rule,
checks the planners before any work and says which table columns apply to it (`applies`).

Two sources: `EnvSource` (highway-env seeds: an env id, a seed and a number of episodes, traffic
replaying the human's log or reacting) and `RecordingSource` (the recorded vehicles of CommonRoad
files, `--mode`, `--goal`, `--max-episodes` drawn with the seed).

The third, the stored attack scenes, lives in adversary (a higher layer: it may import this
package, never the other way round): `adversary.crash.evaluate_source.AttackSceneSource(scenes_dir,
count, seed)`, the command `adversary evaluate`. Its `scenarios()` are the first `count` scenes of
the directory's index.json, in order (`adversary.crash.scenes.load_record`); `prepared` true and
`prepare` a no-op (the scene already holds its recorded `HumanLog`, highway-env or
`adversary.crash.recorded`'s); `recorded_log` that log; `drive` the scene's closed loop without an
attack, `adversary.crash.judge.rollout` with no generated tracks, through the world its kind builds
(`adversary.crash.scene_source`: `HighwaySource`, `RecordedSource`), measured from the handover
(`SceneSource.handover_step`); `row` that record with `episode` set to the scene's name; `applies`
jerk and the human's distance (no red lights). `evaluate(AttackSceneSource(...), planners, out)`
writes the same results.json, episodes.csv and table.md as the other two.

Implementations are frozen dataclasses: workers get them pickled, and results must not depend on
which process ran a scenario.
"""

from riskmap.evaluation.sources.base import OPTIONAL_COLUMNS, Scenario, ScenarioSource, planner_label
from riskmap.evaluation.sources.env import EnvScenario, EnvSource
from riskmap.evaluation.sources.recordings import RecordedScenario, RecordingSource, recorded_traffic

__all__ = ["OPTIONAL_COLUMNS", "EnvScenario", "EnvSource", "RecordedScenario", "RecordingSource", "Scenario",
           "ScenarioSource", "planner_label", "recorded_traffic"]
