"""Kill-and-resume tests: `make test` kills each long command mid-write halfway through its run;
`make test-faults` (marker `faults`) adds the kill after the first write and at the last write."""

import pytest

from tests.reliability.faults import KILL_POINTS


def kill_point_params():
    """The KILL_POINTS as pytest params: "middle" always, the others under the `faults` marker."""
    return [pytest.param(p, marks=() if p == "middle" else pytest.mark.faults) for p in KILL_POINTS]
