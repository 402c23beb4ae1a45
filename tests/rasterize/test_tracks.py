"""`Tracks`: shapes checked once, and the recorder's whole record as one."""

import gymnasium as gym
import highway_env  # noqa: F401
import numpy as np
import pytest

from rasterize import Tracks
from rasterize.highway import TrafficRecorder
from rasterize.scene import STATE_DIM


def _tracks(agents=3, steps=4, **changed) -> Tracks:
    fields = {"states": np.zeros((agents, steps, STATE_DIM)), "valid": np.ones((agents, steps), bool),
              "sizes": np.full((agents, 2), [5.0, 2.0]), "kinds": np.zeros(agents, np.int8)}
    return Tracks(**(fields | changed))


def test_consistent_arrays_make_tracks_and_are_held_as_given():
    states = np.arange(3 * 4 * STATE_DIM, dtype=np.float64).reshape(3, 4, STATE_DIM)
    tracks = _tracks(states=states, ids=np.array([7, -1, 2]))
    assert tracks.states is states and tracks.num_agents == 3 and tracks.num_steps == 4
    assert _tracks(agents=0, steps=0).num_agents == 0 and _tracks().ids is None


@pytest.mark.parametrize("field, value", [
    ("states", np.zeros((3, 4, 5))),             # not 6 state columns
    ("states", np.zeros((3, 4))),
    ("valid", np.ones((3, 5), bool)),            # steps differ from the states'
    ("valid", np.ones((2, 4), bool)),
    ("sizes", np.ones((3, 3))),
    ("sizes", np.ones((4, 2))),
    ("kinds", np.zeros(2, np.int8)),
    ("ids", np.arange(4)),
])
def test_a_mismatched_field_is_named(field, value):
    with pytest.raises(ValueError, match=rf"Tracks\.{field} must have shape"):
        _tracks(**{field: value})


def _old_arrays(recorder: TrafficRecorder):
    """What `TrafficRecorder.arrays()` returned, built here by fancy indexing over its rows."""
    steps, agents, rows = zip(*recorder._rows)
    states = np.zeros((len(recorder._sizes), recorder.num_steps, STATE_DIM))
    states[list(agents), list(steps)] = np.array(rows)
    valid = np.zeros(states.shape[:2], dtype=bool)
    valid[list(agents), list(steps)] = True
    return states, valid, np.array(recorder._sizes, dtype=float).reshape(-1, 2), np.array(recorder._kinds, np.int8)


def test_the_recorder_gives_its_record_as_tracks():
    env = gym.make("highway-v0", config={"simulation_frequency": 10, "vehicles_count": 5})
    env.reset(seed=0)
    base = env.unwrapped
    recorder = TrafficRecorder(base.road, base.vehicle, dt_s=0.1)
    for _ in range(4):
        recorder.record()
        base.road.act()
        base.road.step(0.1)
    tracks = recorder.tracks()
    assert recorder.tracks() is tracks                  # cached until the next record
    assert tracks.num_steps == 4 and tracks.num_agents == len(base.road.vehicles) + len(base.road.objects)
    got_all = (tracks.states, tracks.valid, tracks.sizes, tracks.kinds)
    for got, expected in zip(got_all, _old_arrays(recorder)):
        assert got.dtype == expected.dtype
        np.testing.assert_array_equal(got, expected)
    assert tracks.ids is None and tracks.valid.all()
    np.testing.assert_array_equal(tracks.states[recorder.ego_id, -1], recorder.latest_state(recorder.ego_id))
    recorder.record()
    assert recorder.tracks() is not tracks and recorder.tracks().num_steps == 5
    env.close()
