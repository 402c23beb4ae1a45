"""Every long `riskmap` command, killed at an atomic write and resumed, ends as an uninterrupted
run ends (tests/reliability/faults.py)."""

import pytest

from tests.reliability.conftest import kill_point_params
from tests.reliability.faults import Reference


def _collect(out, resume):
    return ["riskmap", "collect", "--env", "highway-v0", "--episodes", "3", "--seed", "0",
            "--out", str(out), "--quiet"] + (["--resume"] if resume else [])


@pytest.fixture(scope="module")
def collect_reference(tmp_path_factory):
    return Reference(_collect, tmp_path_factory.mktemp("collect"))


@pytest.mark.parametrize("point", kill_point_params())
def test_collect(collect_reference, point, tmp_path):
    collect_reference.check_kill_and_resume(point, tmp_path / "out")
