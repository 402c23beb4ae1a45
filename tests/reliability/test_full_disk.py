"""A disk that fills up mid-run: the command ends with one line and exit 2, every file it left is
whole, and `--resume` on a disk with room again ends as an uninterrupted run ends.

The small disk is a tmpfs mounted in a private mount namespace (`unshare`), grown in place
(`mount -o remount,size=`) before the resume; the test is skipped where namespaces are not
allowed."""

import json
import shlex
import shutil
import subprocess
import sys

import numpy as np
import pytest

from tests.reliability.faults import ROOT, Reference, leftovers, snapshot

SCRIPT = """
set -u
mount -t tmpfs -o size={small} tmpfs {mnt} || exit 97
{first} 2>{mnt_parent}/first.err; echo $? > {mnt_parent}/first.rc
cp -a {mnt}/out {mnt_parent}/full
mount -o remount,size=64m {mnt}
{again} 2>{mnt_parent}/again.err; echo $? > {mnt_parent}/again.rc
cp -a {mnt}/out {mnt_parent}/resumed
"""


def _namespaces_allowed() -> bool:
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "-rm", "true"], capture_output=True, check=False)
    return probe.returncode == 0


pytestmark = pytest.mark.skipif(not _namespaces_allowed(),
                                reason="needs unshare (user and mount namespaces) for a tmpfs")


def run_on_small_disk(argv_for, small: str, folder):
    """Run `argv_for(out, resume=False)` with `out` on a tmpfs of size `small`, then grow the
    tmpfs and run `argv_for(out, resume=True)`. Returns (first rc, first stderr, the folder as the
    full disk left it, rc of the resume, the folder after the resume)."""
    mnt = folder / "mnt"
    mnt.mkdir()
    python = [sys.executable, "-m"]
    script = SCRIPT.format(small=small, mnt=shlex.quote(str(mnt)),
                           mnt_parent=shlex.quote(str(folder)),
                           first=shlex.join(python + argv_for(mnt / "out", False)),
                           again=shlex.join(python + argv_for(mnt / "out", True)))
    env = {"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin", "PYTHONHASHSEED": "0"}
    done = subprocess.run(["unshare", "-rm", "bash", "-c", script], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    read = lambda name: (folder / name).read_text()
    return (int(read("first.rc")), read("first.err"), folder / "full", int(read("again.rc")),
            folder / "resumed")


def _whole(path) -> None:
    """Raise if a file the run left cannot be read back."""
    if path.suffix == ".json":
        json.loads(path.read_text())
    elif path.suffix == ".npz":
        with np.load(path, allow_pickle=False) as data:
            for key in data.files:
                data[key]


def _collect(out, resume):
    return ["riskmap", "collect", "--env", "highway-v0", "--episodes", "3", "--seed", "0",
            "--out", str(out), "--quiet"] + (["--resume"] if resume else [])


def test_collect_on_a_full_disk_stops_with_one_line_and_resumes(tmp_path):
    reference = Reference(_collect, tmp_path)
    # Room for the manifest, the index and the first shard (about 17 kB), not for the second.
    rc, err, full, again, resumed = run_on_small_disk(_collect, "36k", tmp_path)
    assert rc == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "No space left on device" in lines[0] and "--resume" in lines[0]
    assert "shards/episode_" in lines[0]            # names the file it could not write
    assert not leftovers(full)
    kept = [p for p in full.rglob("*") if p.is_file()]
    assert any(p.suffix == ".npz" for p in kept)     # finished work is kept ...
    for path in kept:
        _whole(path)                                 # ... and every file is whole
    assert again == 0
    assert snapshot(resumed) == reference.expected
