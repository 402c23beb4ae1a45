"""Atomic file writes: write beside the target, then rename, so readers never see half a file.

Every atomic write of a process is numbered, which gives the reliability suite exact places to
kill a run (tests/reliability): with the environment variable `RISKMAP_KILL_AT=N` the process
kills itself with SIGKILL at its Nth atomic write, right after the rename; `N:mid` kills it with
the temporary file written but not yet renamed. `RISKMAP_WRITE_LOG=FILE` appends the target of
each atomic write to FILE (one line each), so a test can count an uninterrupted run's writes.
"""

from __future__ import annotations

import json
import os
import signal
import tempfile
from pathlib import Path

import numpy as np

_writes = 0   # atomic writes made by this process, for RISKMAP_KILL_AT


def _fault_point(path: Path, stage: str) -> None:
    """Kill this process here when RISKMAP_KILL_AT names this write and stage ("after"/"mid")."""
    spec = os.environ.get("RISKMAP_KILL_AT")
    if not spec:
        return
    number, _, where = spec.partition(":")
    if int(number) == _writes and (where or "after") == stage:
        os.kill(os.getpid(), signal.SIGKILL)


def _log_write(path: Path) -> None:
    log = os.environ.get("RISKMAP_WRITE_LOG")
    if log:
        with open(log, "a") as f:
            f.write(f"{path}\n")


def atomic_write(path: Path, write) -> None:
    global _writes
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _writes += 1
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file ordinary permissions
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        _fault_point(path, "mid")
        os.replace(tmp, path)
    except OSError as err:
        Path(tmp).unlink(missing_ok=True)
        if err.filename is None:   # raised writing to the file object: name the target
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _log_write(path)
    _fault_point(path, "after")


def write_json(path: Path, data) -> None:
    atomic_write(path, lambda f: f.write((json.dumps(data, indent=2, sort_keys=True) + "\n").encode()))


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    atomic_write(path, lambda f: np.savez_compressed(f, **arrays))


def read_npz(path: Path, what: str, fix: str) -> dict[str, np.ndarray]:
    """Every array of the npz at `path`; a damaged file is one InputError naming `what` it is
    and the `fix`."""
    import zipfile

    from rasterize.errors import InputError

    try:
        with np.load(path) as data:
            return {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise InputError(f"{what} {path} is corrupt or truncated ({type(err).__name__}); {fix}"
                         ) from None
