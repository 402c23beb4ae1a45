"""The training-run helper every trainer uses (riskmap/infra/training_run.py): the commit point,
the files derived from it, --resume, the best epoch and the run folder's refusal."""

import json
import math

import pytest
import torch

from rasterize.errors import InputError
from riskmap.infra.checkpoint import load_state, save_state
from riskmap.infra.training_run import STATE, STATE_FORMAT, TrainingRun, csv_log

# Validation values per epoch: epoch 1 improves on 0, 2 does not, 3 does.
VALS = [3.0, 1.0, 2.0, 0.5]
SETTINGS = {"lr": 0.1, "epochs": 4}


class Killed(Exception):
    """Stands for the process dying where it is raised."""


def _die(model):
    raise Killed()


def _fit(out, epochs=4, resume=False, settings=None, die_publishing=None):
    """A tiny loop on the helper: each epoch draws its batch from torch's generator (so the
    random state must resume too) and commits a row with val = VALS[epoch]; `die_publishing`:
    the epoch whose files are never written (killed right after its commit)."""
    torch.manual_seed(0)
    model = torch.nn.Linear(2, 1)
    optimizer = torch.optim.Adam(model.parameters(), lr=0.1)
    run = TrainingRun(out, resume, metric="val", best={"val": math.inf},
                      settings={**SETTINGS, "epochs": epochs, **(settings or {})}, may_change=("epochs",))
    run.refuse()
    run.resume_from(model, optimizer)
    run.lock()
    run.publishes(log=csv_log(["epoch", "loss", "val"]), kind="test", last=True,
                  sidecar=lambda epoch: {"epoch": epoch, "best": run.best})
    run.republish(model)
    for epoch in range(run.first_epoch, epochs):
        loss = model(torch.randn(8, 2)).pow(2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if epoch == die_publishing:
            run.publish = _die
        run.commit(model, optimizer, {"epoch": epoch, "loss": loss.item(), "val": VALS[epoch]})
    return run


def _files(out):
    """Every file of a run folder but its lock: bytes, the state by content."""
    files = {}
    for path in sorted(out.iterdir()):
        if path.name == ".lock":
            continue
        if path.name == STATE:
            state = load_state(path)
            files[path.name] = {k: v for k, v in state.items() if k not in ("model", "optimizer", "rng")}
            files["weights"] = [t.tolist() for t in state["model"].values()]
        else:
            files[path.name] = path.read_bytes()
    return files


@pytest.mark.parametrize("killed", [1, 3])
def test_a_run_killed_between_commit_and_its_files_resumes_to_the_uninterrupted_files(tmp_path, killed):
    """Killed right after committing epoch 1 (the best so far) or 3 (the last and best): the
    resumed run writes that epoch's log row and best.* again, then trains on where there is more."""
    full = _fit(tmp_path / "full")
    assert full.best_epoch == 3 and full.best_value == 0.5
    assert (tmp_path / "full" / "log.csv").read_text().splitlines()[0] == "epoch,loss,val"
    assert json.loads((tmp_path / "full" / "best.json").read_text())["epoch"] == 3
    assert json.loads((tmp_path / "full" / "last.json").read_text())["kind"] == "test"
    cut = tmp_path / "cut"
    with pytest.raises(Killed):
        _fit(cut, die_publishing=killed)      # committed, its log row and best.* not written
    assert load_state(cut / STATE)["epoch"] == killed
    assert (cut / "log.csv").read_text().count("\n") == killed + 1        # header and earlier rows
    assert json.loads((cut / "best.json").read_text())["epoch"] == (0 if killed == 1 else 1)
    resumed = _fit(cut, resume=True)
    assert (resumed.best_epoch, resumed.log) == (full.best_epoch, full.log)
    assert _files(cut) == _files(tmp_path / "full")


def test_the_state_holds_what_resume_needs_in_one_spelling(tmp_path):
    _fit(tmp_path / "run", epochs=2)
    state = load_state(tmp_path / "run" / STATE)
    assert set(state) == {"model", "optimizer", "epoch", "best", "log", "rng", "settings", "format_version"}
    assert state["format_version"] == STATE_FORMAT.version
    assert state["epoch"] == 1 and state["best"] == state["log"][1] and state["settings"]["epochs"] == 2


def test_a_folder_holding_a_run_needs_resume_and_the_same_settings(tmp_path):
    out = tmp_path / "run"
    TrainingRun(out, False).refuse()          # nothing there yet
    _fit(out, epochs=2)
    with pytest.raises(InputError, match="already holds a training run; pass --resume"):
        TrainingRun(out, False).refuse()
    with pytest.raises(InputError, match="already holds a training run"):
        _fit(out, epochs=3)
    with pytest.raises(InputError, match="was trained with other settings; resume with the same"):
        _fit(out, epochs=3, resume=True, settings={"lr": 0.5})
    assert _fit(out, epochs=3, resume=True).epoch == 2       # more epochs may be asked for
    # Resumed with --resume on an empty folder: a fresh run.
    assert _fit(tmp_path / "empty", epochs=1, resume=True).epoch == 0


def test_the_best_epoch_by_a_metric_lower_or_higher(tmp_path):
    lower = TrainingRun(tmp_path, False, metric="val")
    assert lower.best_value == math.inf and lower.best_epoch is None
    assert lower.better({"val": 1e9}) and not lower.better({"val": math.nan})
    higher = TrainingRun(tmp_path, False, metric=lambda row: row["val"]["ap"], higher=True)
    assert higher.best_value == -math.inf
    assert higher.better({"val": {"ap": 0.0}}) and not higher.better({"val": {"ap": None}})
    model = torch.nn.Linear(1, 1)
    optimizer = torch.optim.SGD(model.parameters(), lr=0.1)
    for epoch, ap in enumerate([0.2, 0.5, 0.5, 0.4]):
        higher.commit(model, optimizer, {"epoch": epoch, "val": {"ap": ap}})
    assert higher.best_epoch == 1 and higher.best_value == 0.5 and len(higher.log) == 4


def _old_spelling(path, best=None, drop_epoch=False):
    """Rewrite the state at `path` as earlier trainers spelled it (guard, CRASH): "optimiser",
    "config", "history", "torch_rng", and `best` as they kept it."""
    state = load_state(path)
    old = {"model": state["model"], "optimiser": state["optimizer"], "torch_rng": state["rng"],
           "config": state["settings"], "history": state["log"], "epoch": state["epoch"],
           "best": state["best"] if best is None else best}
    if drop_epoch:
        old.pop("epoch")
    save_state(path, old)


@pytest.mark.parametrize("best", ["row", "value", "value_and_epoch", "no_epoch"])
def test_a_state_of_the_old_spelling_resumes(tmp_path, best):
    full = _fit(tmp_path / "full")
    old = tmp_path / "old"
    _fit(old, epochs=2)
    kept = {"row": None, "value": 1.0, "value_and_epoch": {"val_ap": 1.0, "epoch": 1},
            "no_epoch": None}[best]
    _old_spelling(old / STATE, kept, drop_epoch=best == "no_epoch")
    resumed = _fit(old, resume=True)
    assert resumed.log == full.log and resumed.best == full.best
    assert _files(old) == _files(tmp_path / "full")
    assert "optimizer" in load_state(old / STATE) and "optimiser" not in load_state(old / STATE)


def test_a_resume_from_an_old_spelling_checks_its_settings(tmp_path):
    out = tmp_path / "run"
    _fit(out, epochs=2)
    _old_spelling(out / STATE)
    with pytest.raises(InputError, match="other settings"):
        _fit(out, resume=True, settings={"lr": 0.5})
