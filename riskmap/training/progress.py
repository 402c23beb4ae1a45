"""The progress of a training run (`riskmap train`, `riskmap train-baseline`), resumable after a
kill anywhere.

After every epoch a run writes RUN/state.pt in one atomic write (`riskmap.infra.checkpoint.
save_state`): the weights, the optimizer, the random state, the epoch, the best epoch so far and
the log's rows. That write is the epoch's commit point. Everything else is derived from it and
written after it: RUN/log.csv, RUN/last.* and, when the epoch is the best so far, RUN/best.*. A
resumed run starts from the last state written whole and first writes that epoch's derived files
again (the kill may have come between them), so that it ends exactly as an uninterrupted run.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import torch

from riskmap.infra.atomic import atomic_write
from riskmap.infra.checkpoint import load_state, read_sidecar, save_state
from riskmap.infra.rundir import refuse_unless_resume

STATE = "state.pt"


def refuse_unless_resume_run(out: Path, resume: bool) -> None:
    """Stop unless `resume` when `out` holds a training run (its state, or the last checkpoint of
    a run begun before state.pt)."""
    for marker in (STATE, "last.json"):
        refuse_unless_resume(out, "a training run", marker, resume)


def read_progress(out: Path, kind: str) -> dict | None:
    """The state `commit` last wrote to `out`, None for a run without a finished epoch.

    A run begun before state.pt resumes from its last checkpoint, last_optimizer.pt and the rows
    of log.csv up to the checkpoint's epoch (a kill could have left one twice), without a random
    state."""
    out = Path(out)
    if (out / STATE).exists():
        return load_state(out / STATE)
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
    return {"train": side["train"], "epoch": side["epoch"], "best": side["best"],
            "log": [rows[e] for e in sorted(rows)], "rng": None,
            "model": load_file(str(out / "last.safetensors")),
            "optimizer": torch.load(out / "last_optimizer.pt", weights_only=True)}


def commit(out: Path, model: torch.nn.Module, optimizer: torch.optim.Optimizer, epoch: int,
           best: dict, log: list[dict], settings: dict) -> None:
    """Write the state after `epoch` (the epoch's commit point; `settings`: the run's plain
    settings, compared on resume)."""
    save_state(Path(out) / STATE, {
        "model": {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()},
        "optimizer": optimizer.state_dict(), "rng": torch.get_rng_state(),
        "epoch": epoch, "best": best, "log": log, "train": settings})


def restore(state: dict, model: torch.nn.Module, optimizer: torch.optim.Optimizer) -> None:
    """Load a state's weights, optimizer and random state (what the run held after its epoch)."""
    model.load_state_dict(state["model"])
    optimizer.load_state_dict(state["optimizer"])
    if state["rng"] is not None:
        torch.set_rng_state(state["rng"])


def write_log(path: Path, fields: list[str], rows: list[dict]) -> None:
    """log.csv with one row per finished epoch, written whole."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fields, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write(Path(path), lambda f: f.write(buffer.getvalue().encode()))
