"""The one collect driver (`riskmap.data.collect_source`): both `riskmap collect` sources go
through it, and it does claiming, resume and the manifest for any source."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import riskmap.data.collect_source as driver
from rasterize.errors import InputError
from riskmap.cli import main

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "commonroad"


def test_both_cli_sources_go_through_the_one_driver(tmp_path, monkeypatch):
    pytest.importorskip("commonroad")
    seen = []
    real = driver.run_parallel

    def spy(fn, items, workers, initializer=None):
        seen.append((type(initializer.args[0]).__name__, list(items)))
        return real(fn, items, workers, initializer=initializer)

    monkeypatch.setattr(driver, "run_parallel", spy)
    assert main(["collect", "--env", "intersection-v0", "--episodes", "1", "--out",
                 str(tmp_path / "sim"), "--quiet"]) == 0
    assert main(["collect", "--from-commonroad", str(FIXTURES), "--out", str(tmp_path / "rec"),
                 "--quiet"]) == 0
    assert seen == [("EnvCollectSource", [0]), ("RecordingCollectSource", list(range(8)))]


@dataclass(frozen=True)
class _Config:
    seed: int = 0

    def to_dict(self) -> dict:
        return {"env_id": "fake", "seed": self.seed}


@dataclass(frozen=True)
class _FakeSource:
    """Items without windows; `fail` raises at that item; `made` records what was made."""

    config: _Config = _Config()
    fail: int | None = None
    made: list = field(default_factory=list)
    unit = "item"
    label = "collect fake"

    def items(self) -> range:
        return range(3)

    def worker_state(self) -> str:
        return "state"

    def windows(self, state, item: int) -> tuple[list, dict]:
        assert state == "state"
        if item == self.fail:
            raise RuntimeError("killed")
        self.made.append(item)
        return [], {"episode": item, "windows": 0, "simulated_s": 1.0, "ego_crashed": False,
                    "ego_off_network": False, "group": f"g{item % 2}"}

    def manifest_extra(self, infos: list[dict]) -> dict:
        return {"order": [i["episode"] for i in infos]}


def test_driver_claims_resumes_and_adds_the_source_extra(tmp_path):
    out = tmp_path / "d"
    with pytest.raises(RuntimeError):
        driver.collect_source(_FakeSource(fail=2), out, progress=False)
    assert driver.read_episode_info(driver.shard_path(out, 1))["episode"] == 1
    with pytest.raises(InputError, match="--resume"):
        driver.collect_source(_FakeSource(), out, progress=False)
    with pytest.raises(InputError, match="different configuration"):
        driver.collect_source(_FakeSource(config=_Config(seed=1)), out, resume=True, progress=False)
    source = _FakeSource()
    manifest = driver.collect_source(source, out, resume=True, progress=False)
    assert source.made == [2]                                   # finished items are kept
    assert manifest["order"] == [0, 1, 2] and manifest["counts"]["episodes"] == 3
    index = json.loads((out / driver.INDEX).read_text())
    assert [s["group"] for s in index["shards"]] == ["g0", "g1", "g0"]


def test_a_run_failing_before_its_first_shard_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError):
        driver.collect_source(_FakeSource(fail=0), tmp_path / "d", progress=False)
    assert not (tmp_path / "d").exists()
