"""Shared by the tests of `adversary.attacks`."""


class NeverPlans:
    """A planner stand-in for tests that only look at what wraps it or reads it: reset does nothing,
    and being asked for a plan fails the test."""

    def reset(self, scene):
        pass

    def plan(self, scene):
        raise AssertionError("not called here")
