"""Default checkpoint paths (checkpoints/...) work from any directory, not only the repository's."""

import pytest

from rasterize.errors import InputError
from riskmap.infra.checkpoint import TOOLKIT_ROOT, read_sidecar, resolve_checkpoint
from riskmap.planner.riskmap_planner import load_planner


def test_a_shipped_checkpoint_loads_from_another_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert resolve_checkpoint("checkpoints/riskmap_highway") == TOOLKIT_ROOT / "checkpoints" / "riskmap_highway"
    assert load_planner("checkpoints/riskmap_highway").grid.rows == 50
    # a folder of checkpoints (CRASH's selectors) is found the same way
    assert read_sidecar("checkpoints/crash_selector_highway/selector_mam", kind="crash_selector")


def test_a_local_checkpoint_wins_over_the_shipped_one_and_a_missing_one_is_named(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "riskmap_highway.json").write_text("{}")
    assert resolve_checkpoint("checkpoints/riskmap_highway") == tmp_path.joinpath(
        "checkpoints", "riskmap_highway").relative_to(tmp_path)
    with pytest.raises(InputError, match="checkpoint checkpoints/no_such not found"):
        read_sidecar("checkpoints/no_such")
