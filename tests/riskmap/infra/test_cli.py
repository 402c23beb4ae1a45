"""Command options made from config dataclasses (riskmap.infra.cli)."""

import argparse
from dataclasses import dataclass, field

import pytest

from riskmap.infra.cli import add_config_options, config_from_args, positive_int


@dataclass(frozen=True)
class Example:
    data: str
    episodes: int = 3
    rate_hz: float = 10.0
    envs: tuple[str, ...] = ("highway-v0",)
    limit: int | None = None
    note: str = field(default="x", metadata={"help": "from the field"})


def _parser(**kw) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(exit_on_error=False)
    add_config_options(parser, Example, "data", "episodes", "rate_hz", "envs", "limit", "note", **kw)
    return parser


def test_defaults_and_types_come_from_the_dataclass():
    config = config_from_args(Example, _parser().parse_args(["--data", "d"]))
    assert config == Example("d")
    config = config_from_args(Example, _parser().parse_args(
        ["--data", "d", "--episodes", "5", "--rate-hz", "2.5", "--envs", "a,b", "--limit", "7"]))
    assert config == Example("d", 5, 2.5, ("a", "b"), 7)


def test_required_renamed_typed_and_help():
    parser = _parser(flags={"episodes": "--count"}, option_types={"episodes": positive_int},
                     help={"data": "where"}, choices={"note": ("x", "y")})
    with pytest.raises((SystemExit, argparse.ArgumentError)):
        parser.parse_args([])                                # --data is required (no default)
    assert config_from_args(Example, parser.parse_args(["--data", "d", "--count", "2"])).episodes == 2
    with pytest.raises((SystemExit, argparse.ArgumentError)):
        parser.parse_args(["--data", "d", "--count", "0"])   # positive_int
    with pytest.raises((SystemExit, argparse.ArgumentError)):
        parser.parse_args(["--data", "d", "--note", "z"])    # choices
    text = parser.format_help()
    assert "where" in text and "from the field" in text


def test_an_unknown_field_is_a_programming_error():
    with pytest.raises(ValueError, match="no field 'nope'"):
        add_config_options(argparse.ArgumentParser(), Example, "nope")


def test_a_refused_path_is_one_line_not_a_traceback(tmp_path, capsys):
    from riskmap.cli import main

    blocked = tmp_path / "file"
    blocked.write_text("x")                    # a file where a directory's parent should be
    assert main(["collect", "--env", "highway-v0", "--episodes", "1", "--out",
                 str(blocked / "data")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("riskmap collect: error: ") and str(blocked / "data") in err
    assert "\n" not in err and "check that the path exists" in err


@pytest.mark.parametrize("content, words", [
    ('{"config": {}}', "not a checkpoint sidecar"),
    ("[1, 2]", "not a checkpoint sidecar"),
    ('{"kind": "bc"}', r"is a behaviour-cloning baseline checkpoint \(kind 'bc'\), not a risk-map"),
    ('{"kind": null}', "not a checkpoint sidecar"),
])
def test_a_sidecar_of_another_kind_is_named(tmp_path, content, words):
    from rasterize.errors import InputError
    from riskmap.infra.checkpoint import read_sidecar

    (tmp_path / "ck.safetensors").write_bytes(b"")
    (tmp_path / "ck.json").write_text(content)
    with pytest.raises(InputError, match=words):
        read_sidecar(tmp_path / "ck")


@pytest.mark.parametrize("planner", ["riskmap_highway", "riskmap_st_highway"])
@pytest.mark.parametrize("damage, words", [("drop", "has no 'model' section"),
                                           ("extra", "'model' section of its sidecar does not fit")])
def test_a_sidecar_without_its_model_section_is_one_line_exit_2(tmp_path, capsys, planner, damage, words):
    import json
    import shutil
    from pathlib import Path

    from riskmap.cli import main

    source = Path(__file__).resolve().parents[3] / "checkpoints" / planner
    shutil.copy(source.with_suffix(".safetensors"), tmp_path / "ck.safetensors")
    sidecar = json.loads(source.with_suffix(".json").read_text())
    if damage == "drop":
        del sidecar["model"]
    else:
        sidecar["model"]["wings"] = 2
    (tmp_path / "ck.json").write_text(json.dumps(sidecar))
    assert main(["drive", "--checkpoint", str(tmp_path / "ck"), "--env", "highway-v0", "--episodes", "1",
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err
    assert not (tmp_path / "out").exists()
