"""Planner display names: `name=` in a `py:` SPEC, the default short name of every SPEC kind, and
names made unique within one run, all from the one SPEC parser (riskmap.registry)."""

import pytest

from rasterize.errors import InputError
from riskmap.registry import cached_planner, display_name, display_names, make_planner, split_name
from tests.broken_planners import Broken

BROKEN = "py:tests.broken_planners:Broken"


class KeyRecorder(Broken):
    """A factory that takes any key, so a `name=` passed on to it would show up in `keys`."""

    def __init__(self, seed: int = 0, **keys):
        super().__init__(seed=seed)
        self.keys = keys


def test_a_name_given_is_the_display_name_and_leaves_the_spec_without_it():
    spec = f"{BROKEN}?fault=kmh&name=kmh-broken"
    assert display_name(spec) == "kmh-broken"
    assert split_name(spec) == (f"{BROKEN}?fault=kmh", "kmh-broken")
    assert split_name(f"{BROKEN}?name=solo") == (BROKEN, "solo")          # no `?` left behind
    assert split_name(f"{BROKEN}?name=a%2Bb") == (BROKEN, "a+b")          # URL-quoted, as every value


def test_the_name_never_reaches_the_factory():
    planner = make_planner("py:tests.riskmap.test_registry_names:KeyRecorder?gap_s=2&name=gap2", seed=4)
    assert planner.keys == {"gap_s": 2} and planner.seed == 4
    # Broken takes no `name`: passed on, it would be refused as a key the factory does not take
    assert make_planner(f"{BROKEN}?fault=kmh&name=b").faults == {"kmh"}


def test_two_names_of_one_planner_share_its_cached_instance():
    assert cached_planner(f"{BROKEN}?name=first", 5) is cached_planner(f"{BROKEN}?name=second", 5)


@pytest.mark.parametrize("spec, name", [
    ("idm", "idm"),
    ("yielding", "yielding"),
    ("cv", "cv"),
    ("replay", "replay"),
    ("riskmap:checkpoints/riskmap_highway", "riskmap_highway"),
    ("riskmap:checkpoints/riskmap_highway.safetensors", "riskmap_highway"),
    ("cnn:checkpoints/bc_cnn_highway", "bc_cnn_highway"),
    ("cnn_lstm:checkpoints/bc_cnn_lstm_us101", "bc_cnn_lstm_us101"),
    ("cnn-lstm:checkpoints/bc_cnn_lstm_us101", "bc_cnn_lstm_us101"),
    ("rvsg:/abs/path/bc_rvsg_intersection", "bc_rvsg_intersection"),
    ("py:riskmap_example_planner:GapKeeper?desired_speed=25&headway_s=2", "GapKeeper"),
    ("py:package.module:Outer.make", "make"),
    ("guard:riskmap:checkpoints/riskmap_highway", "guard-riskmap_highway"),
    ("guard-always:cv", "guard-always-cv"),
    (f"guard:{BROKEN}?fault=kmh&name=kmh", "guard-kmh"),     # the inner planner's own name
    ("gap-keeper:25", "gap-keeper-25"),
    ("someplugin:data/run 1/model.safetensors", "someplugin-model"),
])
def test_every_spec_kind_has_a_short_default_name(spec, name):
    assert display_name(spec) == name


def test_names_are_unique_within_a_run_and_a_given_name_is_kept():
    specs = ["riskmap:runs/a/best", "riskmap:runs/b/best", f"{BROKEN}?name=best-2", "cv",
             f"{BROKEN}?fault=kmh&name=cv", "riskmap:runs/c/best"]
    assert display_names(specs) == {
        "riskmap:runs/a/best": "best", "riskmap:runs/b/best": "best-3", f"{BROKEN}?name=best-2": "best-2",
        "cv": "cv-2", f"{BROKEN}?fault=kmh&name=cv": "cv", "riskmap:runs/c/best": "best-4"}
    assert display_names(["idm", "cv"]) == {"idm": "idm", "cv": "cv"}


def test_one_name_given_to_two_planners_is_refused():
    with pytest.raises(InputError, match="both named 'x'; give each its own name="):
        display_names([f"{BROKEN}?name=x", f"{BROKEN}?fault=kmh&name=x"])


@pytest.mark.parametrize("query", ["name=", "name", "name=a/b", "name=..", "name=-x", "name=a%20b",
                                   "name=" + "n" * 65, "name=a&name=b"])
def test_a_bad_name_is_one_line_naming_the_spec(query):
    spec = f"{BROKEN}?{query}"
    with pytest.raises(InputError) as err:
        make_planner(spec)
    message = str(err.value)
    assert BROKEN in message and "\n" not in message
    assert "give it once" in message or "use 1 to 64 letters" in message
