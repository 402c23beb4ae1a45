"""The one rule every long command applies to its `--out` directory before it writes anything.

An output directory that already holds work is continued only with `--resume`, and only with the
settings it was started with; otherwise the command stops with one line naming `--out` and the fix.
A claimed directory has one writer: a second run on it while the first is alive stops at once
(`lock_out_dir`, an advisory lock on `--out/.lock`).
What a command compares on resume is its `settings` minus the keys that may change between
sittings (`may_change`: more episodes, other worker counts). The settings are then written with
the package version and git commit (`riskmap.infra.provenance`).

    previous = claim_out_dir(out, holds="driven episodes", marker="episodes", resume=resume,
                             settings_file="run.json", settings={"config": ..., "planner": spec},
                             may_change=("config.episodes",))
"""

from __future__ import annotations

import json
from pathlib import Path

from rasterize.errors import InputError
from riskmap.infra.atomic import write_json
from riskmap.infra.formats import VERSION_KEY, Format
from riskmap.infra.provenance import provenance


def holds_work(path: Path) -> bool:
    """True for an existing file or a directory holding anything but its lock file (a run killed
    right after claiming its directory left only that)."""
    path = Path(path)
    return path.is_file() or (path.is_dir() and any(p.name != LOCK_FILE for p in path.iterdir()))


def read_settings(path: Path) -> dict:
    """A settings/manifest JSON written by an earlier run; unreadable is an InputError."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        raise InputError(f"{path} is unreadable; delete {Path(path).parent} and start again") from None


def _without(settings: dict, keys: tuple[str, ...]) -> dict:
    """`settings` with dotted `keys` removed (one level of nesting), JSON-normalised."""
    plain = json.loads(json.dumps(settings))
    for key in keys:
        head, _, tail = key.partition(".")
        if tail and isinstance(plain.get(head), dict):
            plain[head].pop(tail, None)
        elif not tail:
            plain.pop(head, None)
    return plain


def refuse_unless_resume(out: Path, holds: str, marker: str | None, resume: bool) -> None:
    """Stop when `out/marker` (or `out` itself, marker None) already holds work and not `resume`,
    or when another run is writing `out` right now (`refuse_if_locked`)."""
    out = Path(out)
    if not resume and holds_work(out / marker if marker else out):
        raise InputError(f"--out {out} already holds {holds}; pass --resume to continue or choose "
                         "another --out")
    refuse_if_locked(out)


def refuse_if_locked(out: Path) -> None:
    """InputError when another process holds `out`'s lock, checked without creating anything:
    a command checks this first, validates its inputs, and only then makes and locks `out`
    (`lock_out_dir`), so that bad input leaves no --out behind."""
    import fcntl
    import os

    lock = Path(out) / LOCK_FILE
    if Path(out).resolve() in _HELD or not lock.is_file():
        return
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return                       # unreadable: lock_out_dir will say why
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        raise InputError(f"--out {out} is being written by another run right now; wait for it to "
                         "finish or choose another --out") from None
    finally:
        os.close(fd)                 # closing drops the probe's own lock


def check_same_settings(out: Path, settings_file: str, settings: dict,
                        may_change: tuple[str, ...] = (), differs: str = "other settings",
                        file_format: Format | None = None) -> dict | None:
    """The settings an earlier run wrote to `out/settings_file` (None if none; upgraded by
    `file_format` when the file is versioned); InputError if they differ from `settings` outside
    `may_change`."""
    path = Path(out) / settings_file
    if not path.exists():
        return None
    previous = read_settings(path)
    if file_format is not None:
        previous = file_format.read(previous, where=path)
    mine = _without(settings, may_change + (VERSION_KEY,))
    theirs = _without(previous, may_change + tuple(provenance()) + (VERSION_KEY,))
    if theirs != mine:
        raise InputError(f"--out {out} was made with {differs}; resume with the same settings or "
                         "choose another --out")
    return previous


LOCK_FILE = ".lock"
_HELD: dict[Path, int] = {}      # out directory -> descriptor of its lock, for this process's life


def lock_out_dir(out: Path) -> None:
    """Become the one writer of `out`: an advisory lock on `out/.lock`, held until this process
    ends (the system drops it when the process dies, killed or not). Another process holding it
    makes this an InputError at once; this process may claim its own directory again.
    The new writer then deletes the temporary files of atomic writes a killed writer left."""
    import fcntl
    import os

    out = Path(out).resolve()
    if out in _HELD:
        return
    out.mkdir(parents=True, exist_ok=True)
    fd = os.open(out / LOCK_FILE, os.O_CREAT | os.O_RDWR, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise InputError(f"--out {out} is being written by another run right now; wait for it to "
                         "finish or choose another --out") from None
    _HELD[out] = fd
    for orphan in out.rglob(".*.tmp"):
        orphan.unlink(missing_ok=True)


def claim_out_dir(out: Path, *, holds: str, marker: str | None, resume: bool, settings_file: str,
                  settings: dict, may_change: tuple[str, ...] = (), differs: str = "other settings",
                  file_format: Format | None = None) -> dict | None:
    """Apply the rule of the module docstring, then write `settings` (with provenance, and
    stamped with `file_format`'s version when given) to `out/settings_file`; returns the previous
    settings (upgraded by `file_format`), or None for a fresh run."""
    refuse_unless_resume(out, holds, marker, resume)
    previous = (check_same_settings(out, settings_file, settings, may_change, differs, file_format)
                if resume else None)
    lock_out_dir(out)
    written = {**settings, **provenance()}
    write_json(Path(out) / settings_file, file_format.stamp(written) if file_format else written)
    return previous
