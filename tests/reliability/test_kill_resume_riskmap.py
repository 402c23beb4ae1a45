"""Every long `riskmap` command, killed at an atomic write and resumed, ends as an uninterrupted
run ends (tests/reliability/faults.py).

Each command runs tiny (a few seconds): a 3-episode intersection dataset made once per module,
3 epochs on 8 windows at 25 cells, 2 short episodes, made-up guard windows.

Beyond these points, every atomic write of each command here (killed right after it and with it
half done) was swept once by hand; all resumed equal.

Findings fixed (command, kill point: symptom -> cause -> fix):
- train, train-baseline (middle, last): a repeated log.csv row, a different best/last and a
  diverging resumed run -> each epoch appended to log.csv, then wrote best.*,
  last_optimizer.pt, last.safetensors, last.json one by one (a kill between them left the weights
  of one epoch with the optimizer and progress of another) -> RUN/state.pt holds weights,
  optimizer, random state, epoch, best and log rows, written whole once per epoch (the commit);
  log.csv, best.* and last.* are written from it after it and again on resume
  (riskmap/infra/training_run.py).
- guard train (right after the final epoch's state.pt): history.json lacked the last epoch ->
  it was written after state.pt, and a resumed run with no epoch left never wrote it again; best.*
  was written before the commit -> history.json and best.* are written from the committed state
  after it, and again on resume.
- guard collect (middle): a resumed run's risk-map-driven seen/unseen episodes differed -> the
  planner was made once per driver, seeded with the seed of the first job that used it (the
  training seed in a whole run, the job's own in a resumed one) -> one planner per driver and seed.
"""

from pathlib import Path

import numpy as np
import pytest

from tests.reliability.conftest import kill_point_params
from tests.reliability.faults import ROOT, Reference, run_cli

COMMONROAD = ROOT / "tests" / "fixtures" / "commonroad"


def _resume(resume):
    return ["--resume"] if resume else []


def _collect(out, resume):
    return ["riskmap", "collect", "--env", "highway-v0", "--episodes", "3", "--seed", "0",
            "--out", str(out), "--quiet"] + _resume(resume)


@pytest.fixture(scope="module")
def collect_reference(tmp_path_factory):
    return Reference(_collect, tmp_path_factory.mktemp("collect"))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Three short intersection episodes (27 windows), the training commands' data."""
    data = tmp_path_factory.mktemp("data") / "intersection"
    done = run_cli(["riskmap", "collect", "--env", "intersection-v0", "--episodes", "3", "--seed",
                    "11", "--out", str(data), "--quiet"])
    assert done.returncode == 0, done.stderr[-3000:]
    return data


TINY_TRAINING = ["--epochs", "3", "--batch-size", "4", "--max-windows", "8", "--seed", "0"]


def _train(data):
    def argv(out, resume):
        # The sample cache in OUT/cache: a killed run leaves it half filled for the resumed one.
        return ["riskmap", "train", "--data", str(data), "--out", str(out), "--resolution", "25",
                "--lr", "0.001", "--device", "cpu", "--workers", "0", "--cache", str(out / "cache"),
                "--quiet", *TINY_TRAINING] + _resume(resume)
    return argv


@pytest.fixture(scope="module")
def train_folder(tmp_path_factory):
    return tmp_path_factory.mktemp("train")


@pytest.fixture(scope="module")
def train_reference(dataset, train_folder):
    return Reference(_train(dataset), train_folder)


@pytest.fixture(scope="module")
def train_baseline_reference(dataset, tmp_path_factory):
    def argv(out, resume):
        return ["riskmap", "train-baseline", "cnn", "--data", str(dataset), "--out", str(out),
                "--quiet", *TINY_TRAINING] + _resume(resume)
    return Reference(argv, tmp_path_factory.mktemp("baseline"))


@pytest.fixture(scope="module")
def drive_reference(train_reference, train_folder, tmp_path_factory):
    checkpoint = train_folder / "reference" / "best"     # the tiny risk-map planner trained above

    def argv(out, resume):
        return ["riskmap", "drive", "--checkpoint", str(checkpoint), "--env", "intersection-v0",
                "--episodes", "2", "--seed", "0", "--out", str(out), "--quiet"] + _resume(resume)
    return Reference(argv, tmp_path_factory.mktemp("drive"))


@pytest.fixture(scope="module")
def evaluate_reference(tmp_path_factory):
    def argv(out, resume):
        return ["riskmap", "evaluate", "--planners", "idm,cv", "--env", "intersection-v0",
                "--episodes", "2", "--episode-s", "4", "--seed", "0", "--workers", "1",
                "--out", str(out), "--quiet"] + _resume(resume)
    # table.md prints the planners' milliseconds per plan (a clock); results.json holds its numbers.
    return Reference(argv, tmp_path_factory.mktemp("evaluate"), ignore={"table.md"})


@pytest.fixture(scope="module")
def evaluate_commonroad_reference(tmp_path_factory):
    def argv(out, resume):
        return ["riskmap", "evaluate", "--commonroad", str(COMMONROAD), "--planners", "cv",
                "--workers", "1", "--out", str(out), "--quiet"] + _resume(resume)
    # the one table layout prints milliseconds per plan here too (a clock); results.json holds its numbers
    return Reference(argv, tmp_path_factory.mktemp("evaluate_commonroad"), ignore={"table.md"})


@pytest.fixture(scope="module")
def guard_collect_reference(tmp_path_factory):
    def argv(out, resume):
        return ["riskmap", "guard", "collect", "--out", str(out), "--seen-envs", "highway-v0",
                "--unseen-envs", "intersection-v0", "--train-episodes", "3", "--seen-episodes", "1",
                "--unseen-episodes", "1", "--planner-every", "99", "--episode-s", "2",
                "--quiet"] + _resume(resume)
    return Reference(argv, tmp_path_factory.mktemp("guard_collect"))


def _guard_windows(path: Path, n: int, seed: int) -> None:
    """Made-up guard windows (the layout of `riskmap guard collect`) whose time to contact is short
    when the separation closes to overlap: learnable, so that validation AP moves between epochs;
    with decision frames, so that the alert threshold is chosen on them (and written again on
    resume)."""
    from riskmap.guard.features import EDGE_DIM, NODE_DIM, OBSERVED
    from riskmap.infra.atomic import write_npz

    rng = np.random.default_rng(seed)
    label = np.arange(n) % 3 == 0
    start = rng.uniform(15, 30, n)
    end = np.where(label, rng.uniform(-1, 2, n), rng.uniform(10, 30, n))
    edge = np.repeat(np.linspace(start, end, OBSERVED).T[..., None], EDGE_DIM, axis=2)
    node = rng.normal(size=(n, NODE_DIM)).astype(np.float32)
    ttc = np.where(label, rng.uniform(0.1, 2.0, n), np.inf).astype(np.float32)
    write_npz(path, {"node_u": node, "node_i": node.copy(), "edge": edge.astype(np.float32),
                     "mask": np.ones((n, OBSERVED), bool), "ttc_s": ttc,
                     "neighbour": np.ones(n, np.int32), "last_step": np.arange(n, dtype=np.int32),
                     "frame_node_u": node, "frame_node_i": node.copy(), "frame_edge": edge.astype(np.float32),
                     "frame_mask": np.ones((n, OBSERVED), bool), "frame": (np.arange(n) // 2).astype(np.int32),
                     "frames": np.array([(n + 1) // 2], np.int32)})


@pytest.fixture(scope="module")
def guard_train_reference(tmp_path_factory):
    folder = tmp_path_factory.mktemp("guard_train")
    for seed, (split, n) in enumerate([("train", 48), ("val", 18), ("seen", 18), ("unseen", 18)]):
        _guard_windows(folder / "data" / "jobs" / f"{split}_x.npz", n, seed)

    def argv(out, resume):
        return ["riskmap", "guard", "train", "--data", str(folder / "data"), "--out", str(out),
                "--epochs", "5", "--patience", "2", "--quiet"] + _resume(resume)
    return Reference(argv, folder)


# Every command above, by the name of its `<command>_reference` fixture.
COMMANDS = ("collect", "train", "train_baseline", "drive", "evaluate", "evaluate_commonroad", "guard_collect",
            "guard_train")


@pytest.mark.parametrize("point", kill_point_params())
@pytest.mark.parametrize("command", COMMANDS)
def test_killed_and_resumed(command, point, request, tmp_path):
    """Killed at `point` and resumed, `command` ends as its uninterrupted run ended."""
    request.getfixturevalue(f"{command}_reference").check_kill_and_resume(point, tmp_path / "out")


def test_guard_train_reference_chooses_its_threshold_on_the_frames(guard_train_reference):
    """The runs compared above go through the validation-frame threshold, not the fixed one."""
    import json

    sidecar = json.loads((guard_train_reference.out / "best.json").read_text())
    assert "validation" in sidecar["alert_threshold_source"]
    assert sidecar["validation_alert_ratio"] <= 0.05


def _after_last(reference: Reference, name: str) -> str:
    """The RISKMAP_KILL_AT value right after the uninterrupted run's last write of file `name`."""
    return str(max(i for i, target in enumerate(reference.targets, 1) if Path(target).name == name))


@pytest.mark.parametrize("command", [pytest.param("train", marks=pytest.mark.faults),
                                     pytest.param("train_baseline", marks=pytest.mark.faults),
                                     "guard_train"])
def test_killed_right_after_the_final_epoch_is_committed(command, request, tmp_path):
    """The state of the last epoch is written, the files derived from it are not: the resumed run
    trains no more and writes them (no kill point above lands there; "middle" and "last" cover
    the training commands' other epochs)."""
    reference = request.getfixturevalue(f"{command}_reference")
    reference.check_kill_and_resume(_after_last(reference, "state.pt"), tmp_path / "out")
