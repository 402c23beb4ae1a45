"""The `py:` SPEC and entry-point plug-ins, resolved by the one SPEC parser."""

import pytest

from rasterize.errors import InputError
from riskmap.registry import is_planner, make_planner
from tests.broken_planners import Broken


def test_py_spec_makes_the_planner_with_typed_keys_and_the_seed():
    planner = make_planner("py:tests.broken_planners:Broken?fault=kmh", seed=7)
    assert isinstance(planner, Broken) and planner.faults == {"kmh"} and planner.seed == 7
    explicit = make_planner("py:tests.broken_planners:Broken?seed=3", seed=7)
    assert explicit.seed == 3 and explicit.faults == {"none"}
    assert make_planner("py:riskmap.planner.baselines:ConstantVelocityPlanner").__class__.__name__ \
        == "ConstantVelocityPlanner"      # a factory without a seed gets none


@pytest.mark.parametrize("spec, says", [
    ("py:no_such_module_xyz:Planner", "cannot be imported"),
    ("py:tests.broken_planners:Missing", "has no 'Missing'"),
    ("py:tests.broken_planners:FAULTS", "not a factory"),
    ("py:tests.broken_planners:not_a_planner", "made a str, not a planner"),
    ("py:tests.broken_planners:Broken?colour=red", "does not take these keys"),
    ("py:tests.broken_planners:Broken?fault=melt", "could not be made (ValueError"),
    ("py:tests.broken_planners:Broken?fault=nan&fault=kmh", "gives 'fault' twice"),
    ("py:tests.broken_planners:Broken?fault", "key=value pairs"),
    ("py:tests.broken_planners", "py:package.module:Factory"),
])
def test_a_bad_py_spec_is_one_line_naming_it(spec, says):
    with pytest.raises(InputError) as err:
        make_planner(spec)
    message = str(err.value)
    assert says in message and spec.split("?")[0] in message and "\n" not in message


def test_is_planner_wants_an_instance_with_reset_and_plan():
    assert is_planner(Broken())
    assert not is_planner(Broken) and not is_planner("text") and not is_planner(object())
    assert is_planner(make_planner("idm"))       # drives itself


def test_an_entry_point_plugin_is_found_by_name():
    # The guard is declared in pyproject.toml as entry points of `riskmap.planners`.
    with pytest.raises(InputError, match="not found|checkpoint|unknown"):
        make_planner("guard:riskmap:/no/such/checkpoint")
    with pytest.raises(InputError, match="unknown planner spec"):
        make_planner("nosuchplugin:x")
