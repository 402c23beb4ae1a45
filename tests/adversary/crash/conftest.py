"""Scenes shared by the CRASH tests."""

import pytest

from adversary.crash.scene_sweep import EnvSweep, record_scenes


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Two highway-v0 attack scenes. Seed 500 episode 1: the car ahead in the next lane can cut in
    front of the replayed human."""
    out = tmp_path_factory.mktemp("scenes") / "highway"
    record_scenes(EnvSweep("highway-v0", 500, first_episode=1), 2, out, progress=False)
    return out
