import subprocess
import sys

from riskmap.cli import main


def _run(*args):
    return subprocess.run([sys.executable, "-m", "riskmap", *args], capture_output=True,
                          text=True, timeout=300)


def test_collect_then_figures(tmp_path):
    data, figs = tmp_path / "data", tmp_path / "figs"
    assert main(["collect", "--env", "intersection-v0", "--episodes", "1", "--seed", "0",
                 "--out", str(data), "--quiet"]) == 0
    assert main(["figures", "scenes", "--data", str(data), "--out", str(figs), "--count", "2"]) == 0
    pngs = sorted(figs.glob("*.png"))
    assert len(pngs) == 2 and all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)


def test_unknown_env_is_one_line_and_leaves_nothing(tmp_path):
    out = tmp_path / "never"
    result = _run("collect", "--env", "nope-v0", "--episodes", "1", "--out", str(out))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown env 'nope-v0'" in lines[0] and "highway-v0" in lines[0]
    assert not out.exists()


def test_missing_dataset_is_one_line(tmp_path):
    result = _run("figures", "scenes", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "f"))
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "riskmap collect" in result.stderr
    assert not (tmp_path / "f").exists()


def test_train_drive_and_plan_figures_from_the_command_line(tmp_path, tiny_dataset, tiny_checkpoint):
    run = tmp_path / "run"
    assert main(["train", "--data", str(tiny_dataset), "--out", str(run), "--resolution", "25",
                 "--epochs", "1", "--batch-size", "4", "--max-windows", "4", "--quiet"]) == 0
    assert (run / "best.safetensors").exists() and (run / "best.json").exists()
    assert main(["figures", "plans", "--checkpoint", str(run / "best"), "--data",
                 str(tiny_dataset), "--out", str(tmp_path / "fig"), "--count", "1"]) == 0
    assert len(list((tmp_path / "fig").glob("plan_*.png"))) == 1
    assert main(["drive", "--planner", "idm", "--env", "intersection-v0", "--episodes", "1",
                 "--out", str(tmp_path / "drive"), "--quiet"]) == 0
    assert (tmp_path / "drive" / "summary.json").exists()


def test_drive_needs_exactly_one_planner(tmp_path):
    result = _run("drive", "--env", "highway-v0", "--episodes", "1", "--out", str(tmp_path / "x"))
    assert result.returncode == 2 and "exactly one of --checkpoint" in result.stderr


def test_missing_checkpoint_is_one_line(tmp_path):
    result = _run("drive", "--checkpoint", str(tmp_path / "nope"), "--env", "highway-v0",
                  "--episodes", "1", "--out", str(tmp_path / "x"))
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "checkpoint" in result.stderr and "not found" in result.stderr
