from dataclasses import replace

import numpy as np
import pytest

from rasterize.errors import InputError
from rasterize.scene import Signal
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


def _signalled(scene, *signals):
    return replace(scene, signals=signals)


def _assert_same_signals(a, b):
    assert len(a) == len(b)
    for sa, sb in zip(a, b):
        np.testing.assert_allclose(sa.stop_line, sb.stop_line, atol=1e-5)
        np.testing.assert_array_equal(sa.times_s, sb.times_s)
        np.testing.assert_array_equal(sa.red, sb.red)


def test_roundtrip_of_signals_ragged_over_scenes_and_times():
    red = Signal([[3.5, -2.0], [3.5, 2.0]], [0.0, 1.25, 4.0], [True, False, True])
    green = Signal([[-1.0, 5.0], [1.0, 5.0]], [0.0], [False])
    scenes = [_signalled(constant_velocity_scene(), red, green), constant_velocity_scene(),
              _signalled(constant_velocity_scene(), green)]
    packed = pack_scenes(scenes)
    assert check_packed(packed, "test") == 3
    assert packed["signal_offsets"].tolist() == [0, 2, 2, 3]
    for i, original in enumerate(scenes):
        _assert_same_signals(unpack_scene(packed, i).signals, original.signals)


def test_shards_without_signals_pack_empty_and_old_shards_unpack_with_none():
    packed = pack_scenes([constant_velocity_scene()])
    assert packed["signal_stop_line"].shape == (0, 2, 2) and packed["signal_times_s"].shape == (0,)
    assert unpack_scene(packed, 0).signals == ()
    # A shard written before signals existed has none of their arrays.
    old = {k: v for k, v in pack_scenes([_signalled(constant_velocity_scene(), Signal(
        [[0.0, 0.0], [0.0, 1.0]], [0.0], [True]))]).items() if not k.startswith("signal_")}
    assert check_packed(old, "old") == 1
    assert unpack_scene(old, 0).signals == ()


def test_partial_or_inconsistent_signal_arrays_are_named():
    packed = pack_scenes([_signalled(constant_velocity_scene(), Signal([[0, 0], [0, 1]], [0.0], [True]))])
    partial = {k: v for k, v in packed.items() if k != "signal_red"}
    with pytest.raises(InputError, match="signal arrays .*signal_red.* missing"):
        check_packed(partial, "shard_x")
    packed["signal_times_s"] = packed["signal_times_s"][:0]
    with pytest.raises(InputError, match="shard_x: signal arrays are inconsistent"):
        check_packed(packed, "shard_x")
