"""The shipped planners' catalogue: one SPEC per planner and family, each naming what checkpoints/ ships."""

from pathlib import Path

import pytest

from rasterize.errors import InputError
from riskmap.planner.shipped import FAMILIES, SHIPPED_PLANNERS, shipped_spec

ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize("family", FAMILIES)
def test_every_shipped_planner_has_a_spec_in_every_family(family):
    for name in SHIPPED_PLANNERS:
        kind, _, path = shipped_spec(name, family).partition(":")
        assert kind == name
        if path:
            assert (ROOT / f"{path}.safetensors").is_file()


def test_a_highway_env_id_names_its_family():
    assert shipped_spec("riskmap", "highway-v0") == "riskmap:checkpoints/riskmap_highway"
    assert shipped_spec("riskmap", "intersection-v0") == shipped_spec("riskmap", "intersection")
    assert shipped_spec("idm", "intersection-v0") == "idm"


@pytest.mark.parametrize(("name", "family"), [("nope", "highway"), ("riskmap", "roundabout")])
def test_an_unknown_planner_or_family_is_an_input_error(name, family):
    with pytest.raises(InputError):
        shipped_spec(name, family)
