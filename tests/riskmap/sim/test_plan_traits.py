"""The planner's optional declarations: one list (`PlannerTraits`), one reader (`traits_of`), and
the table made from that list in docs/guide/your-own-planner.md."""

from pathlib import Path

from riskmap.sim.loop.plan import (
    HumanDriver,
    PlannerTraits,
    declarations_table,
    drives_itself,
    requires_log,
    traits_of,
)

REPO = Path(__file__).resolve().parents[3]


class Bare:
    """A planner that declares nothing."""

    def reset(self, scene):
        pass

    def plan(self, scene):
        raise AssertionError("not driven here")


class SomeDeclared(Bare):
    requires_log = True
    name = "mine"

    def set_log(self, log):
        self.log = log


class Forwarding:
    """A wrapper that declares whatever the planner inside it does."""

    def __init__(self, inner):
        self.inner = inner

    def __getattr__(self, name):
        return getattr(self.inner, name)


def test_a_planner_that_declares_nothing_gets_every_default():
    assert traits_of(Bare()) == PlannerTraits()
    assert traits_of(None) == PlannerTraits()
    assert not drives_itself(Bare()) and not requires_log(Bare())


def test_what_a_planner_declares_is_read_and_the_rest_defaults():
    planner = SomeDeclared()
    traits = traits_of(planner)
    assert traits.requires_log and traits.name == "mine" and not traits.drives_itself
    traits.set_log("the log")
    assert planner.log == "the log"
    assert traits.attach is None and traits.raster is None and traits.guard is None
    assert traits_of(HumanDriver()).drives_itself and drives_itself(HumanDriver())


def test_a_wrapper_declares_what_it_forwards():
    assert traits_of(Forwarding(SomeDeclared())).requires_log
    assert traits_of(Forwarding(Bare())) == PlannerTraits()


def test_every_declaration_says_what_it_means_and_who_reads_it():
    for row, name in zip(declarations_table().splitlines()[2:], PlannerTraits.__dataclass_fields__):
        assert row.startswith(f"| `{name}` |")
    assert all(f.metadata["meaning"] and f.metadata["read_by"]
               for f in PlannerTraits.__dataclass_fields__.values())


def test_the_guide_table_is_the_one_list():
    page = (REPO / "docs" / "guide" / "your-own-planner.md").read_text()
    lines = [line.strip() for line in page.splitlines()]
    table = declarations_table().splitlines()
    start = lines.index(table[0])
    assert lines[start:start + len(table)] == table
