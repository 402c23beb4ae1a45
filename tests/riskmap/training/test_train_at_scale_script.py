"""experiments/train_at_scale.sh, the script for a lent GPU machine, run at its tiny scale."""

import os
import subprocess
import sys
from pathlib import Path

from riskmap.planner.riskmap_planner import load_planner
from riskmap.planner.st_planner import SpaceTimePlanner

ROOT = Path(__file__).resolve().parents[3]


def test_the_scale_script_collects_trains_and_writes_checkpoints(tmp_path):
    out = tmp_path / "scale"
    env = {**os.environ, "OUT": str(out), "SCALE": "tiny",
           "RISKMAP": str(Path(sys.executable).with_name("riskmap"))}
    env.pop("US101", None)
    env.pop("LANKERSHIM", None)
    done = subprocess.run(["bash", str(ROOT / "experiments" / "train_at_scale.sh")], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr[-2000:]
    for name in ("riskmap_st_highway", "riskmap_st_intersection", "riskmap_st_highway_px100",
                 "riskmap_st_intersection_px100"):
        planner = load_planner(out / "checkpoints" / name)
        assert isinstance(planner, SpaceTimePlanner)
        assert planner.raster.rows == (100 if name.endswith("_px100") else 200)
        assert (out / "checkpoints" / f"{name}.log.csv").is_file()
    # resumable: a second run finds everything done and writes the same checkpoints
    again = subprocess.run(["bash", str(ROOT / "experiments" / "train_at_scale.sh")], cwd=ROOT,
                           env=env, capture_output=True, text=True, timeout=1200)
    assert again.returncode == 0, again.stderr[-2000:]
    bad = subprocess.run(["bash", str(ROOT / "experiments" / "train_at_scale.sh")], cwd=ROOT,
                         env={**env, "SCALE": "huge"}, capture_output=True, text=True)
    assert bad.returncode == 2 and "SCALE" in bad.stderr
    for name, value in (("DEADLINE_S", "soon"), ("RASTERS", "200 big")):
        bad = subprocess.run(["bash", str(ROOT / "experiments" / "train_at_scale.sh")], cwd=ROOT,
                             env={**env, name: value}, capture_output=True, text=True)
        assert bad.returncode == 2 and name in bad.stderr, bad.stderr
