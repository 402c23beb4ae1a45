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
              "version", "rollout_s"}
CLOCK_WORDS = ("elapsed", "seconds", "wall", "timing", "plan_ms")   # any key containing one is a clock


def _is_clock(key) -> bool:
    return isinstance(key, str) and (key in CLOCK_KEYS or any(word in key for word in CLOCK_WORDS))


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
    (temporary file complete, not renamed) halfway, "last" mid-write at the last write; a
    RISKMAP_KILL_AT value itself ("N" or "N:mid") is taken as it is."""
    if name not in KILL_POINTS:
        return name
    return {"first": "1", "middle": f"{max(writes // 2, 1)}:mid", "last": f"{writes}:mid"}[name]


def _strip_clock(value):
    if isinstance(value, dict):
        return {k: _strip_clock(v) for k, v in value.items() if not _is_clock(k)}
    if isinstance(value, list):
        return [_strip_clock(v) for v in value]
    return value


def _content(path: Path, out: Path | None = None):
    """What must be equal in a file: parsed content for formats with clocks, bytes otherwise.
    Text naming the output folder `out` itself (a run's settings record its --out) reads $OUT."""
    suffix = path.suffix
    raw = path.read_bytes()
    names = {str(out), str(Path(out).resolve())} if out is not None else set()
    if suffix not in (".npz", ".pt"):
        for name in names:
            raw = raw.replace(name.encode(), b"$OUT")
    if suffix == ".json":
        return _strip_clock(json.loads(raw))
    if suffix == ".jsonl":
        return [_strip_clock(json.loads(line)) for line in raw.decode().splitlines() if line]
    if suffix == ".csv":
        rows = list(csv.DictReader(io.StringIO(raw.decode())))
        return [{k: v for k, v in row.items() if not _is_clock(k)} for row in rows]
    if suffix == ".npz":
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k].tobytes() + str((data[k].dtype, data[k].shape)).encode()
                    for k in sorted(data.files)}
    if suffix == ".pt":
        import torch

        return _strip_clock(_tensor_bytes(torch.load(path, weights_only=True), names))
    return raw


def _tensor_bytes(value, names=frozenset()):
    """Tensors as bytes; strings naming the output folder (one of `names`) read $OUT."""
    import torch

    if isinstance(value, torch.Tensor):
        return value.detach().cpu().numpy().tobytes()
    if isinstance(value, dict):
        return {k: _tensor_bytes(v, names) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_tensor_bytes(v, names) for v in value]
    if isinstance(value, str):
        for name in names:
            value = value.replace(name, "$OUT")
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
        result[str(rel)] = _content(path, out)
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
        self.out = folder / "reference"      # the uninterrupted output (input of later commands)
        log = folder / "writes.log"
        done = run_cli(argv_for(self.out, False), write_log=log)
        assert done.returncode == 0, done.stderr[-3000:]
        self.targets = log.read_text().splitlines()   # the files written, in order
        self.writes = len(self.targets)
        assert self.writes >= 1, "the command made no atomic write; nothing to kill at"
        self.expected = snapshot(self.out, self.ignore)

    def write_number(self, target: str, occurrence: int) -> int:
        """The number (1-based, as RISKMAP_KILL_AT counts) of the `occurrence`th write of
        `target` (a path relative to the output folder)."""
        relative = [Path(t).relative_to(self.out).as_posix() for t in self.targets]
        return [i + 1 for i, t in enumerate(relative) if t == target][occurrence - 1]

    def check_kill_and_resume(self, point: str, out: Path) -> None:
        """Kill a run at `point` (a KILL_POINTS name or a RISKMAP_KILL_AT value), resume it until
        it finishes, and assert its folder equals the uninterrupted one."""
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
