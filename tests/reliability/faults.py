"""Kill a command at exact places and check that `--resume` ends where an uninterrupted run ends.

A run is killed by itself at its Nth atomic write (`RISKMAP_KILL_AT`, see
`riskmap/infra/atomic.py`): after the first write, mid-write (temporary file complete, not yet
renamed) somewhere in the middle, and mid-write at the last write. The resumed folder must equal
the uninterrupted one: bitwise where bytes are deterministic, and by content where a format
carries a clock (`.npz` zip entries, TensorBoard events, timings in JSON and CSV).
"""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np

KILLED = -signal.SIGKILL
ROOT = Path(__file__).resolve().parents[2]

# Files and keys that legitimately differ between two runs of the same settings.
IGNORED_NAMES = {".lock"}
IGNORED_DIRS = {"tb", "cache", "__pycache__"}
CLOCK_KEYS = {"started", "finished", "created", "time_s", "duration_s", "git_commit", "git_dirty",
              "version"}
CLOCK_WORDS = ("elapsed", "seconds", "wall", "timing")   # any key containing one is a clock


def _is_clock(key: str) -> bool:
    return key in CLOCK_KEYS or any(word in key for word in CLOCK_WORDS)


def run_cli(argv: list[str], *, kill_at: str | None = None, write_log: Path | None = None,
            cwd: Path = ROOT, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run `python -m <argv[0]> argv[1:]` (argv[0] is "riskmap" or "adversary") in a child."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}
    env.pop("RISKMAP_KILL_AT", None)
    env.pop("RISKMAP_WRITE_LOG", None)
    if kill_at is not None:
        env["RISKMAP_KILL_AT"] = kill_at
    if write_log is not None:
        env["RISKMAP_WRITE_LOG"] = str(write_log)
    return subprocess.run([sys.executable, "-m", *argv], check=False, cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


KILL_POINTS = ("first", "middle", "last")


def kill_point(name: str, writes: int) -> str:
    """A RISKMAP_KILL_AT value: "first" right after the first atomic write, "middle" mid-write
    (temporary file complete, not renamed) halfway, "last" mid-write at the last write."""
    return {"first": "1", "middle": f"{max(writes // 2, 1)}:mid", "last": f"{writes}:mid"}[name]


def _strip_clock(value):
    if isinstance(value, dict):
        return {k: _strip_clock(v) for k, v in value.items() if not _is_clock(k)}
    if isinstance(value, list):
        return [_strip_clock(v) for v in value]
    return value


def _content(path: Path):
    """What must be equal in a file: parsed content for formats with clocks, bytes otherwise."""
    suffix = path.suffix
    if suffix == ".json":
        return _strip_clock(json.loads(path.read_text()))
    if suffix == ".jsonl":
        return [_strip_clock(json.loads(line)) for line in path.read_text().splitlines() if line]
    if suffix == ".csv":
        rows = list(csv.DictReader(io.StringIO(path.read_text())))
        return [{k: v for k, v in row.items() if not _is_clock(k)} for row in rows]
    if suffix == ".npz":
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k].tobytes() + str((data[k].dtype, data[k].shape)).encode()
                    for k in sorted(data.files)}
    if suffix == ".pt":
        import torch

        return _tensor_bytes(torch.load(path, weights_only=True))
    return path.read_bytes()


def _tensor_bytes(value):
    import torch

    if isinstance(value, torch.Tensor):
        return value.detach().cpu().numpy().tobytes()
    if isinstance(value, dict):
        return {k: _tensor_bytes(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_tensor_bytes(v) for v in value]
    return value


def snapshot(out: Path, ignore: set[str] = frozenset()) -> dict[str, object]:
    """Relative path -> comparable content for every file under `out` (minus clocks and locks;
    temporary files included, so that a leftover is a difference)."""
    result = {}
    for path in sorted(Path(out).rglob("*")):
        rel = path.relative_to(out)
        if not path.is_file() or path.name in IGNORED_NAMES | set(ignore) \
                or any(part in IGNORED_DIRS for part in rel.parts):
            continue
        result[str(rel)] = _content(path)
    return result


def leftovers(out: Path) -> list[str]:
    """Temporary files of atomic writes left in `out` (a killed write may leave one; a finished
    resume must not)."""
    return [str(p.relative_to(out)) for p in Path(out).rglob(".*.tmp")]


class Reference:
    """The uninterrupted run of a command, made once and compared against by every kill point.

    `argv_for(out, resume)` gives the command line for output folder `out`."""

    def __init__(self, argv_for, folder: Path, ignore: set[str] = frozenset()):
        self.argv_for, self.ignore = argv_for, set(ignore)
        log = folder / "writes.log"
        done = run_cli(argv_for(folder / "reference", False), write_log=log)
        assert done.returncode == 0, done.stderr[-3000:]
        self.writes = len(log.read_text().splitlines())
        assert self.writes >= 1, "the command made no atomic write; nothing to kill at"
        self.expected = snapshot(folder / "reference", self.ignore)

    def check_kill_and_resume(self, point: str, out: Path) -> None:
        """Kill a run at `point` (a KILL_POINTS name), resume it until it finishes, and assert
        its folder equals the uninterrupted one."""
        at = kill_point(point, self.writes)
        killed = run_cli(self.argv_for(out, False), kill_at=at)
        assert killed.returncode == KILLED, (at, killed.returncode, killed.stderr[-3000:])
        resumed = run_cli(self.argv_for(out, True))
        assert resumed.returncode == 0, (at, resumed.stderr[-3000:])
        got = snapshot(out, self.ignore)
        assert sorted(got) == sorted(self.expected), (at, sorted(set(got) ^ set(self.expected)))
        for name, content in self.expected.items():
            assert got[name] == content, (at, name)
        assert not leftovers(out), (at, leftovers(out))
