"""Versioned formats (riskmap.infra.formats): one reader per kind of file upgrades every older
layout to today's, one step per version, and refuses a newer one in one line."""

import json

import pytest

from rasterize.errors import InputError
from riskmap.infra.formats import VERSION_KEY, Format


def _two_steps() -> Format:
    return Format("test file", (lambda d: {**d, "a": d.get("a", 1)}, lambda d: {**d, "b": d["a"] + 1}))


def test_an_unversioned_file_is_upgraded_through_every_step_and_stamped():
    fmt = _two_steps()
    assert fmt.version == 2
    assert fmt.read({"x": 0}) == {"x": 0, "a": 1, "b": 2, VERSION_KEY: 2}
    assert fmt.read({"a": 5, VERSION_KEY: 1}) == {"a": 5, "b": 6, VERSION_KEY: 2}   # only the later step
    assert fmt.read(fmt.stamp({"a": 1, "b": 9})) == {"a": 1, "b": 9, VERSION_KEY: 2}  # today's: unchanged


def test_the_reader_leaves_the_callers_dict_alone():
    data = {"x": 0}
    _two_steps().read(data)
    assert data == {"x": 0}


@pytest.mark.parametrize("version, words", [(3, "newer than this toolkit reads (2); install"),
                                            (-1, "not a version"), ("1", "not a version"),
                                            (True, "not a version")])
def test_a_version_this_toolkit_cannot_read_is_one_line(version, words):
    with pytest.raises(InputError, match=r"some/file\.json") as error:
        _two_steps().read({VERSION_KEY: version}, where="some/file.json")
    assert words in str(error.value) and "\n" not in str(error.value)


def test_an_old_spatial_sidecar_plans_as_before_and_a_space_time_one_is_untouched(tmp_path):
    """The sampler defaults of sidecars from before `timing`/`keep_gap` existed live in the
    sidecar format's upgrade, not in the planner."""
    import torch

    from riskmap.infra.checkpoint import SIDECAR_FORMAT, read_sidecar, save_checkpoint
    from riskmap.planner.riskmap_planner import sampler_of

    old = {"kind": "riskmap", "sampler": {"samples": 100}}
    side = SIDECAR_FORMAT.read(old)
    assert sampler_of(side).timing == "uniform" and not sampler_of(side).keep_gap
    assert sampler_of(side).gap_prediction == "straight" and sampler_of(side).samples == 100
    st = {"kind": "riskmap", "planner": "spacetime", "sampler": {"samples": 100}}
    assert SIDECAR_FORMAT.read(st)["sampler"] == {"samples": 100}
    guard = {"kind": "guard_tgat", "sampler": {"x": 1}}
    assert SIDECAR_FORMAT.read(guard)["sampler"] == {"x": 1}

    path = save_checkpoint(tmp_path / "m", torch.nn.Linear(1, 1), {"sampler": {"samples": 7, "timing": "kinematic"}})
    assert json.loads(path.with_suffix(".json").read_text())[VERSION_KEY] == SIDECAR_FORMAT.version
    assert read_sidecar(tmp_path / "m")["sampler"] == {"samples": 7, "timing": "kinematic"}  # written today: as is


def test_a_sidecar_from_a_newer_toolkit_is_refused_naming_it(tmp_path):
    import torch

    from riskmap.infra.checkpoint import read_sidecar, save_checkpoint

    path = save_checkpoint(tmp_path / "m", torch.nn.Linear(1, 1), {})
    data = json.loads(path.with_suffix(".json").read_text())
    path.with_suffix(".json").write_text(json.dumps({**data, VERSION_KEY: 99}))
    with pytest.raises(InputError, match=r"m\.json is a checkpoint sidecar of version 99, newer"):
        read_sidecar(tmp_path / "m")


def test_a_scene_index_from_before_static_vehicles_reads_as_none_and_a_recorded_one_unchanged(tmp_path):
    from adversary.crash.scene_sweep import SCENE_INDEX_FORMAT, read_index

    (tmp_path / "index.json").write_text(json.dumps({"env_id": "highway-v0", "seed": 0, "t0_s": 2.0,
                                                     "scenes": ["a"], "next_episode": 1}))
    assert read_index(tmp_path)["static_agents"] == 0
    recorded = {"recordings": ["x.xml"], "scenes": [], "next_candidate": 0}
    assert "static_agents" not in SCENE_INDEX_FORMAT.read(recorded)


def test_an_attack_run_json_from_before_the_options_reads_with_their_old_values():
    from adversary.crash.attack import AttackConfig
    from adversary.crash.run import ATTACK_RUN_FORMAT

    old = {"planner": "idm", "config": {"selector": "crash"}}
    config = ATTACK_RUN_FORMAT.read(old)["config"]
    assert config["replan_hz"] == AttackConfig.replan_hz and config["validity_terms"] is False
    kept = ATTACK_RUN_FORMAT.read({"config": {"replan_hz": 5, "validity_terms": True}})["config"]
    assert kept == {"replan_hz": 5, "validity_terms": True}
