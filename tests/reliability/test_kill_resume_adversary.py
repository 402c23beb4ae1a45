"""Every long `adversary` command, killed at an atomic write and resumed, ends as an uninterrupted
run ends (tests/reliability/faults.py). The settings are the smallest known to be fast
(tests/adversary); `--workers 1` wherever there is such a flag, so that the process the kill hook
counts in is the one that writes.

Findings this suite made, fixed in the library (command, kill point: symptom; cause -> fix):
- scenes, first: resume refused ("already holds scenes"); a kill before the first index.json left
  scene files only -> resume without an index starts afresh over them (adversary/crash/run.py)
- scenes, middle/last: the killed write's temporary file stayed; no lock -> lock_out_dir (same file)
- attack, middle: resumed records differed; the rest of a cut-off batch was re-batched and a scene's
  numbers depend on its batch -> fixed batch slices, re-run whole, missing records written (run.py)
- guard-data, middle/last: the killed write's temporary file stayed; export took no lock ->
  lock_out_dir (adversary/crash/guard_data.py)
- train-traffic, middle: log.jsonl got an epoch twice (appended before best/state.pt); state.pt was
  not the one commit point -> state.pt holds log, best weights and both RNG states, log.jsonl and
  best.* are derived after it and rewritten on resume (adversary/crash/train_traffic.py)
- train-traffic, at the 2nd epoch's state.pt: the resumed epochs drew other numbers (data order
  reseeded, torch generator reset) -> both generators' states restored from state.pt (same file)
- train-traffic, fixture: 3 episodes or fewer with the default val share raised IndexError (the
  held-out cut past the last episode) -> no val split then, the train windows validate (same file)
- train-selector: labels.jsonl was appended (a kill mid-line leaves a line resume cannot parse) ->
  rewritten whole, atomically, per scene (adversary/crash/train_selector.py)
- search, stress-test: none (the stress-test's index.sqlite is compared by its rows, below).
Harness: `rollout_s` (wall time of the judge's rollouts) is a clock key (faults.py).
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest
import yaml

from tests.adversary.conftest import TINY
from tests.reliability.conftest import kill_point_params
from tests.reliability.faults import Reference, _strip_clock, run_cli

TRAFFIC = "checkpoints/crash_traffic_highway"


def _resume(argv: list[str], resume: bool) -> list[str]:
    return argv + ["--quiet"] + (["--resume"] if resume else [])


# ---------------------------------------------------------------- inputs made once per module

@pytest.fixture(scope="module")
def collected(tmp_path_factory) -> Path:
    """Four highway episodes from `riskmap collect` (train-traffic holds one episode out)."""
    out = tmp_path_factory.mktemp("collected") / "data"
    done = run_cli(["riskmap", "collect", "--env", "highway-v0", "--episodes", "4", "--seed", "0",
                    "--out", str(out), "--quiet"])
    assert done.returncode == 0, done.stderr[-3000:]
    return out


# ---------------------------------------------------------------- adversary scenes

def _scenes(out, resume):
    # seed 500 from episode 1: the scenes of tests/adversary/crash/test_attack_run.py
    return _resume(["adversary", "scenes", "--env", "highway-v0", "--seed", "500", "--count", "3",
                    "--first-episode", "1", "--out", str(out)], resume)


@pytest.fixture(scope="module")
def scenes_reference(tmp_path_factory):
    return Reference(_scenes, tmp_path_factory.mktemp("scenes"))


# ---------------------------------------------------------------- adversary attack

# table.md carries the seconds per scene (a clock); summary.json holds the same numbers by key.
ATTACK_IGNORE = {"table.md"}


def _attack(scenes: Path, selector: str, planner: str, iterations: int):
    # Three scenes in batches of two: the middle kill lands between the records of one batch.
    def argv(out, resume):
        return _resume(["adversary", "attack", "--planner", planner, "--scenes", str(scenes),
                        "--count", "3", "--selector", selector, "--iterations", str(iterations),
                        "--replan-every", "10", "--batch-size", "2", "--workers", "1",
                        "--traffic-model", TRAFFIC, "--out", str(out)], resume)
    return argv


@pytest.fixture(scope="module")
def attack_distance_reference(scenes_reference, tmp_path_factory):
    # 80 iterations: the car ahead in the next lane of scene 1 cuts in (a collision for guard-data)
    return Reference(_attack(scenes_reference.out, "distance", "replay", 80),
                      tmp_path_factory.mktemp("attack_distance"), ATTACK_IGNORE)


@pytest.fixture(scope="module")
def attack_crash_reference(scenes_reference, tmp_path_factory):
    # CRASH with the shipped selectors against a closed-loop ego (tests/adversary/crash)
    return Reference(_attack(scenes_reference.out, "crash", "idm", 20),
                      tmp_path_factory.mktemp("attack_crash"), ATTACK_IGNORE)


# ---------------------------------------------------------------- adversary guard-data

def _guard_data(attacks: list[Path]):
    def argv(out, resume):
        return _resume(["adversary", "guard-data", *[a for d in attacks for a in ("--attacks", str(d))],
                        "--out", str(out)], resume)
    return argv


@pytest.fixture(scope="module")
def guard_data_reference(attack_distance_reference, attack_crash_reference, tmp_path_factory):
    return Reference(_guard_data([attack_distance_reference.out, attack_crash_reference.out]),
                      tmp_path_factory.mktemp("guard_data"))


# ---------------------------------------------------------------- adversary search

def _search(algorithm: str, seed: int):
    # Seeds that find a collision in 8 evaluations, so the report replays a failure too.
    def argv(out, resume):
        return _resume(["adversary", "search", "--planner", "cv", "--template", "cut_in",
                        "--algorithm", algorithm, "--pop", "4", "--gen", "2", "--episode-s", "4",
                        "--seed", str(seed), "--workers", "1", "--out", str(out)], resume)
    return argv


@pytest.fixture(scope="module")
def search_nsga2_reference(tmp_path_factory):
    return Reference(_search("nsga2", 1), tmp_path_factory.mktemp("search_nsga2"))


@pytest.fixture(scope="module")
def search_random_reference(tmp_path_factory):
    return Reference(_search("random", 0), tmp_path_factory.mktemp("search_random"))


# ---------------------------------------------------------------- adversary train-traffic

def _train_traffic(data: Path):
    def argv(out, resume):
        return _resume(["adversary", "train-traffic", "--data", str(data), "--epochs", "3",
                        "--batch-size", "8", "--max-windows-per-episode", "6", "--threads", "1",
                        "--out", str(out)], resume)
    return argv


@pytest.fixture(scope="module")
def train_traffic_reference(collected, tmp_path_factory):
    return Reference(_train_traffic(collected), tmp_path_factory.mktemp("train_traffic"))


@pytest.mark.parametrize("stage", ["mid", pytest.param("after", marks=pytest.mark.faults)])
def test_train_traffic_killed_between_epochs(train_traffic_reference, stage, tmp_path):
    """Killed at the second epoch's commit (mid-write: resumed from the first epoch's state; after
    it: from the second's, before its log line): the resumed run draws what the uninterrupted one
    drew (both random generators are in the state)."""
    at = f"{train_traffic_reference.write_number('state.pt', 2)}:{stage}"
    train_traffic_reference.check_kill_and_resume(at, tmp_path / "out")


# ---------------------------------------------------------------- adversary train-selector

def _train_selector(data: Path):
    def argv(out, resume):
        return _resume(["adversary", "train-selector", "--traffic-model", TRAFFIC, "--data", str(data),
                        "--label-iterations", "5", "--max-scenes", "4", "--windows-per-episode", "2",
                        "--epochs", "5", "--threads", "1", "--out", str(out)], resume)
    return argv


@pytest.fixture(scope="module")
def train_selector_reference(collected, tmp_path_factory):
    return Reference(_train_selector(collected), tmp_path_factory.mktemp("train_selector"))


# ---------------------------------------------------------------- every command above

# By the name of its `<command>_reference` fixture.
COMMANDS = ("scenes", "attack_distance", "attack_crash", "guard_data", "search_nsga2", "search_random",
            "train_traffic", "train_selector")


@pytest.mark.parametrize("point", kill_point_params())
@pytest.mark.parametrize("command", COMMANDS)
def test_killed_and_resumed(command, point, request, tmp_path):
    """Killed at `point` and resumed, `command` ends as its uninterrupted run ended."""
    request.getfixturevalue(f"{command}_reference").check_kill_and_resume(point, tmp_path / "out")


# ---------------------------------------------------------------- adversary stress-test

# index.sqlite is a derived index, rebuilt from records/ on open; its bytes depend on the order
# rows were inserted in. `_index_rows` compares what it holds instead.
STRESS_IGNORE = {"index.sqlite"}


def _index_rows(out: Path) -> dict[str, object]:
    db = sqlite3.connect(f"file:{out / 'index.sqlite'}?mode=ro", uri=True)
    try:
        return {job: _strip_clock(json.loads(record))
                for job, record in db.execute("SELECT job_id, record FROM jobs")}
    finally:
        db.close()


@pytest.fixture(scope="module")
def stress_test_reference(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stress_test")
    config = folder / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY))

    def argv(out, resume):
        return _resume(["adversary", "stress-test", "--config", str(config), "--workers", "1",
                        "--out", str(out)], resume)
    return Reference(argv, folder, STRESS_IGNORE)


@pytest.mark.parametrize("point", kill_point_params())
def test_stress_test(stress_test_reference, point, tmp_path):
    stress_test_reference.check_kill_and_resume(point, tmp_path / "out")
    rows = _index_rows(tmp_path / "out")
    assert rows == _index_rows(stress_test_reference.out)
    assert sorted(rows) == sorted(p.stem for p in (tmp_path / "out" / "records").glob("*.json"))
