from dataclasses import replace

import numpy as np
import pytest

from rasterize.errors import InputError
from rasterize.scene_io import check_packed, pack_scenes, unpack_scene
from tests.scenes import constant_velocity_scene, straight_lane


def test_roundtrip_with_ragged_agents_and_lanes():
    a = constant_velocity_scene(lanes=[straight_lane(0.0), straight_lane(4.0)])
    b = replace(constant_velocity_scene(), states=a.states[:1], valid=a.valid[:1],
                sizes=a.sizes[:1], kinds=a.kinds[:1], lanes=())
    packed = pack_scenes([a, b])
    assert check_packed(packed, "test") == 2
    for original, i in ((a, 0), (b, 1)):
        back = unpack_scene(packed, i)
        assert back.num_agents == original.num_agents and len(back.lanes) == len(original.lanes)
        np.testing.assert_allclose(back.states, original.states, atol=1e-5)
        for la, lb in zip(original.lanes, back.lanes):
            np.testing.assert_allclose(la.left, lb.left, atol=1e-5)
            assert la.left_line == lb.left_line


def test_check_packed_names_the_bad_array():
    packed = pack_scenes([constant_velocity_scene()])
    packed["valid"] = packed["valid"][:, :1]
    with pytest.raises(InputError, match="valid has shape"):
        check_packed(packed, "shard_x")
