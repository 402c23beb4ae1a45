"""The bookkeeping every training loop shares (`riskmap train`, `riskmap train-baseline`, `riskmap
guard train`, `adversary train-traffic`, `adversary train-selector --objective unrolled`): one
`TrainingRun` per run folder, resumable after a kill anywhere.

- The folder: a run folder that already holds a run is continued only with `--resume`
  (`refuse_unless_resume_run`); one writer at a time (`TrainingRun.lock`).
- The commit point: after every epoch the run writes its resume state (RUN/state.pt unless named
  otherwise) in one atomic write (`TrainingRun.commit`): the weights, the optimizer, the epoch,
  the best epoch so far, the log's rows, the random state where the loop keeps one, the settings,
  and whatever else the trainer adds (`extra`).
- The derived files, written from the committed state right after it (`TrainingRun.publish`):
  the log (log.csv, log.jsonl, history.json: `csv_log`, `jsonl_log`, `json_log`), best.* when the
  committed epoch is the best so far, last.* where the trainer keeps one. A resumed run first
  writes them again (`TrainingRun.republish`: the kill may have come between the commit and them),
  so that it ends exactly as an uninterrupted run.
- `--resume` (`TrainingRun.resume_from`): reload the weights, optimizer, random state, epoch, best
  so far and log rows, after checking that the settings are the run's but for those a resume may
  change.
- The best epoch: by a metric of the log rows that the trainer names (lower is better unless
  `higher`); it is the row of that epoch.

States written by earlier versions still resume: `STATE_FORMAT` reads their keys in every
spelling used before (`SPELLINGS`: "optimiser" for "optimizer", ...) and puts a state without
an epoch at the last epoch of its log; a best written as the metric's value or as {value,
epoch} is taken as the log row of its epoch (`TrainingRun`, which knows the metric). A `riskmap train` run begun before state.pt resumes from its last
checkpoint (`read_checkpoint_run`).

    run = TrainingRun(out, resume, metric="val_ade_m", settings=to_plain(config))
    run.refuse(markers=(STATE, "last.json"))
    run.resume_from(model, optimizer)        # None for a fresh run; checks the settings
    run.lock()
    run.publishes(log=csv_log(fields), sidecar=lambda epoch: {...}, last=True)
    run.republish(model)
    for epoch in range(run.first_epoch, epochs):
        ...
        run.commit(model, optimizer, {"epoch": epoch, **metrics})    # state, then the files
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Callable

import torch

from rasterize.errors import InputError
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.checkpoint import (
    CHECKPOINT_KIND,
    load_state,
    read_sidecar,
    save_checkpoint,
    save_state,
)
from riskmap.infra.formats import Format
from riskmap.infra.rundir import lock_out_dir, refuse_unless_resume

STATE = "state.pt"

# The keys of a resume state, each with the spellings that states written before used; a state
# is written with the first, read in any.
SPELLINGS = {
    "model": ("model", "selector"),
    "optimizer": ("optimizer", "optimiser"),
    "settings": ("settings", "train", "config"),
    "log": ("log", "history"),
    "rng": ("rng", "torch_rng"),
}


def refuse_unless_resume_run(out: Path, resume: bool, holds: str = "a training run",
                             markers: tuple[str | None, ...] = (STATE,)) -> None:
    """Stop unless `resume` when one of `markers` in `out` (None: `out` itself) already holds
    work, or when another run is writing `out` (`riskmap.infra.rundir.refuse_unless_resume`)."""
    for marker in markers:
        refuse_unless_resume(out, holds, marker, resume)


# ------------------------------------------------------------------------------ the log's files

def write_log(path: Path, fields: list[str], rows: list[dict]) -> None:
    """A CSV log with one row per finished epoch, written whole."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fields, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write(Path(path), lambda f: f.write(buffer.getvalue().encode()))


def csv_log(fields: list[str], name: str = "log.csv") -> Callable[[Path, list[dict]], None]:
    """RUN/`name`: the log's rows as CSV with columns `fields`."""
    return lambda out, rows: write_log(Path(out) / name, fields, rows)


def jsonl_log(name: str = "log.jsonl") -> Callable[[Path, list[dict]], None]:
    """RUN/`name`: one JSON line per row, rewritten whole."""
    def write(out: Path, rows: list[dict]) -> None:
        text = "".join(json.dumps(r) + "\n" for r in rows)
        atomic_write(Path(out) / name, lambda f: f.write(text.encode()))
    return write


def json_log(name: str) -> Callable[[Path, list[dict]], None]:
    """RUN/`name`: the rows as one JSON list."""
    return lambda out, rows: write_json(Path(out) / name, rows)


# ------------------------------------------------------------------------------ older runs

def read_checkpoint_run(out: Path, kind: str) -> dict | None:
    """The state of a `riskmap train` / `train-baseline` run begun before state.pt, from its last
    checkpoint, last_optimizer.pt and the rows of log.csv up to the checkpoint's epoch (a kill
    could have left one twice), without a random state; None where there is no last checkpoint."""
    out = Path(out)
    if not (out / "last.json").exists():
        return None
    from safetensors.torch import load_file

    side = read_sidecar(out / "last", kind=kind)
    rows = {}
    if (out / "log.csv").exists():
        for row in csv.DictReader(io.StringIO((out / "log.csv").read_text())):
            if row["epoch"] and int(row["epoch"]) <= side["epoch"]:
                rows[int(row["epoch"])] = {"epoch": int(row["epoch"]),
                                           **{k: float(v) for k, v in row.items() if k != "epoch"}}
    return {"settings": side["train"], "epoch": side["epoch"], "best": side["best"],
            "log": [rows[e] for e in sorted(rows)], "rng": None,
            "model": load_file(str(out / "last.safetensors")),
            "optimizer": torch.load(out / "last_optimizer.pt", weights_only=True)}


def _state_v1(state: dict) -> dict:
    """A resume state from before versions were kept: its keys in today's spelling
    (`SPELLINGS`), an empty log where it held none, and the epoch of its last log row where it
    named no epoch."""
    state = dict(state)
    for key, spellings in SPELLINGS.items():
        for spelling in spellings:
            if spelling in state:
                value = state.pop(spelling)
                state.setdefault(key, value)
    state.setdefault("log", [])
    state.setdefault("epoch", len(state["log"]) - 1)
    return state


# A training run's resume state (state.pt); `TrainingRun.resume_from` upgrades older ones.
STATE_FORMAT = Format("training resume state", (_state_v1,))


# ------------------------------------------------------------------------------ the run

class TrainingRun:
    """One training run in folder `out` (module docstring).

    `state`: the resume state's file name in `out`. `metric`: the log row's key (or a function of
    a row) by which an epoch is the best so far, lower better unless `higher`; `best`: the best
    record before any epoch (the trainer's sidecars show it until an epoch improves on it).
    `random_state`: whether the state holds torch's random generator (a loop that draws from it).
    `settings`: the run's plain settings, kept in the state and compared on resume: the saved
    ones must equal them once the keys `may_change` are taken from these (or `same(saved)` says
    so), else an InputError ending in `fix`. `older()`: the state of a run begun before the
    state file, where the folder lacks it (None: a fresh run)."""

    def __init__(self, out: Path, resume: bool, *, state: str = STATE,
                 metric: str | Callable[[dict], float] | None = None, higher: bool = False,
                 best: dict | None = None, random_state: bool = True, settings: dict | None = None,
                 may_change: tuple[str, ...] = (), same: Callable[[dict], bool] | None = None,
                 fix: str = "resume with the same settings or choose another --out",
                 older: Callable[[], dict | None] | None = None):
        self.out, self.resume = Path(out), resume
        self.path = self.out / state
        self.metric, self.higher = metric, higher
        self.best: dict = dict(best or {})
        self.random_state, self.settings = random_state, settings
        self.may_change, self.same, self.fix, self.older = may_change, same, fix, older
        self.epoch = -1                 # the last committed epoch
        self.log: list[dict] = []
        self.state: dict | None = None  # the state resumed from
        self._log_writer = None
        self._sidecar = None
        self._kind, self._last = CHECKPOINT_KIND, False

    # -------------------------------------------------------------------- the folder

    def refuse(self, holds: str = "a training run", markers: tuple[str | None, ...] | None = None
               ) -> TrainingRun:
        """Stop unless --resume when the folder holds a run (by default: its state file)."""
        refuse_unless_resume_run(self.out, self.resume, holds,
                                 (self.path.name,) if markers is None else markers)
        return self

    def lock(self) -> None:
        """Become the folder's one writer (creates it)."""
        lock_out_dir(self.out)

    # -------------------------------------------------------------------- best so far

    def _value(self, row) -> float | None:
        if self.metric is None or not isinstance(row, dict):
            return None
        try:
            value = self.metric(row) if callable(self.metric) else row[self.metric]
        except (KeyError, TypeError, IndexError):
            return None
        return None if value is None else float(value)

    @property
    def best_epoch(self) -> int | None:
        return self.best.get("epoch")

    @property
    def best_value(self) -> float:
        """The best epoch's metric (inf, or -inf when higher is better, before any)."""
        value = self._value(self.best)
        return (-math.inf if self.higher else math.inf) if value is None else value

    def better(self, row: dict) -> bool:
        """Whether log row `row` beats the best so far (strictly; NaN never does)."""
        value = self._value(row)
        if value is None:
            return False
        return value > self.best_value if self.higher else value < self.best_value

    # -------------------------------------------------------------------- resume

    @property
    def first_epoch(self) -> int:
        """The epoch to train next."""
        return self.epoch + 1

    @property
    def resumed(self) -> bool:
        return self.state is not None

    def _upgraded_best(self, best, log: list[dict]) -> dict:
        """A state's best as a log row (older states: the metric's value alone, or with its epoch)."""
        if isinstance(best, dict) and (self._value(best) is not None or self.metric is None):
            return best
        epoch = best.get("epoch") if isinstance(best, dict) else None
        for row in log:
            if epoch is not None and row.get("epoch") == epoch:
                return dict(row)
            if epoch is None and isinstance(best, (int, float)) and self._value(row) == float(best):
                return dict(row)
        if isinstance(best, (int, float)) and isinstance(self.metric, str):
            return {self.metric: float(best)}
        return dict(self.best)

    def resume_from(self, model: torch.nn.Module, optimizer: torch.optim.Optimizer) -> dict | None:
        """With --resume and a committed state (or, without the state file, what `older` reads
        of a run begun before it): check the settings, load the weights, the optimizer and the
        random state, and continue from its epoch, best and log. Returns the state (its extra
        keys included), None for a fresh run."""
        if not self.resume:
            return None
        if self.path.exists():
            state = load_state(self.path)
        else:
            state = self.older() if self.older is not None else None
        if state is None:
            return None
        state = STATE_FORMAT.read(state, where=self.path)
        saved = state.get("settings")
        if saved is not None and not self._same_settings(saved):
            raise InputError(f"--out {self.out} was trained with other settings; {self.fix}")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        if self.random_state and state.get("rng") is not None:
            torch.set_rng_state(state["rng"])
        self.epoch, self.log = state["epoch"], list(state["log"])
        self.best = self._upgraded_best(state.get("best"), self.log)
        self.state = state
        return state

    def _same_settings(self, saved: dict) -> bool:
        if self.same is not None:
            return self.same(saved)
        if self.settings is None:
            return True
        free = {k: self.settings[k] for k in self.may_change if k in self.settings}
        return saved | free == self.settings

    # -------------------------------------------------------------------- commit and publish

    def publishes(self, *, log: Callable[[Path, list[dict]], None] | None = None,
                  sidecar: Callable[[int], dict] | None = None, kind: str = CHECKPOINT_KIND,
                  last: bool = False) -> TrainingRun:
        """The files derived from a committed state: `log(out, rows)`; best.* (and last.* where
        `last`) of checkpoint `kind` with `sidecar(epoch)`, asked for only when written."""
        self._log_writer, self._sidecar, self._kind, self._last = log, sidecar, kind, last
        return self

    def commit(self, model: torch.nn.Module, optimizer: torch.optim.Optimizer, row: dict,
               extra: dict | None = None) -> bool:
        """Epoch `row["epoch"]` is done: add `row` to the log, take it as the best if it is,
        write the state (the epoch's commit point; `extra`: more values for the state), then the
        files derived from it (`publish`). Returns whether the epoch is the best so far."""
        improved = self.better(row)
        self.epoch, self.log = row["epoch"], self.log + [row]
        if improved:
            self.best = dict(row)
        state = {"model": {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()},
                 "optimizer": optimizer.state_dict(), "epoch": self.epoch, "best": self.best,
                 "log": self.log}
        if self.random_state:
            state["rng"] = torch.get_rng_state()
        if self.settings is not None:
            state["settings"] = self.settings
        save_state(self.path, STATE_FORMAT.stamp({**state, **(extra or {})}))
        self.publish(model)
        return improved

    def publish(self, model: torch.nn.Module) -> None:
        """The files derived from the committed state: the log, then best.* when the committed
        epoch is the best so far, then last.*; `model` holds the committed weights."""
        if self._log_writer is not None:
            self._log_writer(self.out, self.log)
        is_best = self.best_epoch is not None and self.best_epoch == self.epoch
        if self._sidecar is None or not (is_best or self._last):
            return
        sidecar = self._sidecar(self.epoch)
        if is_best:
            save_checkpoint(self.out / "best", model, sidecar, kind=self._kind)
        if self._last:
            save_checkpoint(self.out / "last", model, sidecar, kind=self._kind)

    def republish(self, model: torch.nn.Module) -> None:
        """A resumed run writes its state's files again first: a kill may have come between the
        commit and them."""
        if self.resumed:
            self.publish(model)
