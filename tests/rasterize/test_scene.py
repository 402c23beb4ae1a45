from dataclasses import replace

import numpy as np
import pytest

from rasterize.config import Extent, RasterConfig
from rasterize.errors import InputError
from rasterize.scene import Scene
from tests.scenes import constant_velocity_scene


def test_past_drops_future():
    scene = constant_velocity_scene(n_past=2, n_future=4)
    past = scene.past()
    assert past.num_steps == 3 and past.num_future_steps == 0
    np.testing.assert_array_equal(past.states, scene.states[:, :3])


def test_ego_future():
    scene = constant_velocity_scene(n_past=2, n_future=4, dt=0.5, ego_speed=2.0)
    np.testing.assert_allclose(scene.ego_future_xy()[:, 0], [1.0, 2.0, 3.0, 4.0])


def test_nan_state_is_rejected_with_location():
    scene = constant_velocity_scene()
    states = scene.states.copy()
    states[1, 3, 0] = np.nan
    with pytest.raises(InputError, match="agent 1 at time index 3"):
        replace(scene, states=states)


def test_nan_in_invalid_state_is_ignored_and_zeroed():
    scene = constant_velocity_scene()
    states, valid = scene.states.copy(), scene.valid.copy()
    states[1, 0] = np.nan
    valid[1, 0] = False
    fixed = replace(scene, states=states, valid=valid)
    assert np.isfinite(fixed.states).all()


def test_shape_errors_name_the_field():
    scene = constant_velocity_scene()
    with pytest.raises(InputError, match="Scene.valid"):
        replace(scene, valid=scene.valid[:, :-1])
    with pytest.raises(InputError, match="ego has no valid state"):
        valid = scene.valid.copy()
        valid[0, scene.current_index] = False
        replace(scene, valid=valid)


@pytest.mark.parametrize("side", ["front_m", "back_m", "left_m", "right_m"])
def test_extent_must_contain_the_ego(side):
    sides = dict(front_m=10.0, back_m=10.0, left_m=10.0, right_m=10.0)
    sides[side] = -5.0
    with pytest.raises(InputError, match="does not contain the ego"):
        RasterConfig(Extent(**sides))


def test_rotated_scene_keeps_distances():
    scene = constant_velocity_scene()
    rot = scene.rotated(1.1)
    d0 = np.linalg.norm(scene.states[0, :, :2] - scene.states[1, :, :2], axis=1)
    d1 = np.linalg.norm(rot.states[0, :, :2] - rot.states[1, :, :2], axis=1)
    np.testing.assert_allclose(d0, d1)
    assert isinstance(rot, Scene)


def test_ego_perturbation_turns_and_shifts_only_the_current_ego_pose():
    scene = constant_velocity_scene()       # ego heading east at the origin
    moved = scene.with_ego_perturbed(np.pi / 2, 1.5)
    np.testing.assert_allclose(moved.ego_state()[:4], [0.0, 1.5, 0.0, 1.0], atol=1e-12)
    changed = np.argwhere(np.any(moved.states != scene.states, axis=-1))
    assert changed.tolist() == [[0, scene.current_index]]
