"""experiments/planning_sweep.py: variants of a checkpoint's planning section, driven side by side."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
CHECKPOINT = ROOT / "checkpoints" / "riskmap_st_intersection"


def _sweep(tmp_path: Path) -> dict:
    table = tmp_path / "table.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / "planning_sweep.py"), "--checkpoint", str(CHECKPOINT),
         "--env", "intersection-v0", "--episodes", "1", "--seed", "300",
         "--variants", str(tmp_path / "variants"), "--out", str(tmp_path / "runs"), "--baseline", "idm=idm",
         "--variant", 'ahead={"time_gap": {"time_gap_s": 1.0, "weight": 100.0, "ahead_only": true}}',
         "--table", str(table)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(table.read_text())


def test_a_variant_is_the_same_weights_with_its_planning_updated_and_a_rerun_resumes(tmp_path):
    first = _sweep(tmp_path)
    assert set(first["rows"]) == {"idm", "ahead"}
    for row in first["rows"].values():
        assert row["episodes"] == 1 and 0 <= row["collisions"] <= 1 and row["distance_m"] > 0
    variant = tmp_path / "variants" / "ahead"
    assert (Path(f"{variant}.safetensors").read_bytes()
            == CHECKPOINT.with_suffix(".safetensors").read_bytes())
    side, original = (json.loads(Path(p).read_text())
                      for p in (f"{variant}.json", CHECKPOINT.with_suffix(".json")))
    assert side["planning"]["time_gap"] == {"time_gap_s": 1.0, "weight": 100.0, "ahead_only": True}
    assert {k: v for k, v in side.items() if k != "planning"} == {k: v for k, v in original.items()
                                                                   if k != "planning"}
    episode = tmp_path / "runs" / "ahead" / "episodes" / "episode_000000.json"
    written = episode.stat().st_mtime_ns
    assert _sweep(tmp_path) == first                    # resumed: the finished episode is kept
    assert episode.stat().st_mtime_ns == written
