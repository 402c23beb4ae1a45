import subprocess
import sys

from riskmap.cli import main


def _run(*args):
    return subprocess.run([sys.executable, "-m", "riskmap.cli", *args], capture_output=True,
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
