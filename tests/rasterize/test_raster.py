from dataclasses import replace

import numpy as np
import pytest

from rasterize.config import Extent, RasterConfig
from rasterize.raster import CHANNEL_INDEX, CHANNELS, history_intensity, rasterize_scene
from rasterize.scene import Lane, LineType
from tests.scenes import UNIT_RASTER, constant_velocity_scene, straight_lane


def _mask(rows, cols, shape=(20, 20)):
    m = np.zeros(shape, dtype=bool)
    m[rows[0]:rows[1] + 1, cols[0]:cols[1] + 1] = True
    return m


def test_boxes_pixel_exact():
    raster = rasterize_scene(constant_velocity_scene(), UNIT_RASTER)
    assert raster.shape == (len(CHANNELS), 20, 20) and raster.dtype == np.uint8
    # Ego: x in [-2, 2], y in [-1, 1] -> rows 8..11, cols 9..10.
    np.testing.assert_array_equal(raster[CHANNEL_INDEX["ego"]] > 0, _mask((8, 11), (9, 10)))
    # Agent at (5, 3) facing north, 4 x 2 m: x in [4, 6], y in [1, 5] -> rows 4..5, cols 5..8.
    np.testing.assert_array_equal(raster[CHANNEL_INDEX["agents"]] > 0, _mask((4, 5), (5, 8)))
    assert set(np.unique(raster[CHANNEL_INDEX["ego"]])) == {0, 255}


def test_history_fades_with_age():
    # dt 0.5 s, history 1 s: ego boxes at -1 m (age 0.5 s) and -2 m (age 1 s) relative to now.
    raster = rasterize_scene(constant_velocity_scene(ego_speed=2.0), UNIT_RASTER)
    hist = raster[CHANNEL_INDEX["ego_history"]]
    newer, older = history_intensity(0.5, 1.0, 0.5), history_intensity(1.0, 1.0, 0.5)
    assert 255 > newer > older > 0
    # Box at age 1.0 s spans x in [-4, 0] -> rows 10..13; at age 0.5 s x in [-3, 1] -> rows 9..12.
    assert hist[13, 9] == older and hist[9, 9] == newer and hist[11, 9] == newer
    assert hist[8, 9] == 0 and hist[14, 9] == 0
    # The agent stands still, so its history lies under its current box.
    assert (raster[CHANNEL_INDEX["agents_history"]] > 0).sum() == 8


def test_lanes_pixel_exact():
    # Lane centred 4 m to the ego's left (y = 4), 4 m wide: y in [2, 6] -> cols 4..7 drivable.
    lane = straight_lane(4.0, width=4.0, left=LineType.DASHED, right=LineType.SOLID)
    raster = rasterize_scene(constant_velocity_scene(lanes=[lane]), UNIT_RASTER)
    drivable = raster[CHANNEL_INDEX["drivable"]] > 0
    expected = np.zeros((20, 20), bool)
    expected[:, 4:8] = True
    np.testing.assert_array_equal(drivable, expected)
    # The solid right boundary (y = 2) falls on the edge between cols 7 and 8; the centre line
    # y = 4 on the edge between cols 5 and 6: each is a single full-height column.
    solid_cols = np.flatnonzero(raster[CHANNEL_INDEX["lane_solid"]].any(axis=0))
    centre_cols = np.flatnonzero(raster[CHANNEL_INDEX["lane_centre"]].any(axis=0))
    assert len(solid_cols) == 1 and solid_cols[0] in (7, 8)
    assert len(centre_cols) == 1 and centre_cols[0] in (5, 6)
    assert raster[CHANNEL_INDEX["lane_solid"]][:, solid_cols[0]].all()
    # The dashed left boundary is painted 3 m in every 7.33 m; a 1-px line includes both of its
    # end pixels, so a 3 m dash on 1 m pixels paints 4: between 40% and 65% of the column.
    dashed = raster[CHANNEL_INDEX["lane_dashed"]]
    dashed_col = np.flatnonzero(dashed.any(axis=0))
    assert len(dashed_col) == 1
    assert 0.4 <= (dashed[:, dashed_col[0]] > 0).mean() <= 0.65


def _curvy_scene():
    s = np.linspace(0, 60, 61)
    centre = np.stack([s - 20, 3 * np.sin(s / 10)], axis=1)
    tangent = np.gradient(centre, axis=0)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    lane = Lane(centre, centre + 2 * normal, centre - 2 * normal, LineType.DASHED, LineType.SOLID)
    return constant_velocity_scene(lanes=[lane])


def test_rotating_the_world_leaves_the_raster_unchanged():
    config = RasterConfig(Extent(30.0, 10.0, 20.0, 20.0), rows=200, cols=200, history_s=1.0)
    scene = _curvy_scene()
    base = rasterize_scene(scene, config).astype(int)
    for angle in (0.3, 1.7, -2.9):
        turned = rasterize_scene(scene.rotated(angle), config).astype(int)
        for c, name in enumerate(CHANNELS):
            differing = (np.abs(turned[c] - base[c]) > 0).sum()
            # Only rounding at polygon edges may differ: far below 1% of the painted pixels.
            assert differing <= max(3, 0.01 * (base[c] > 0).sum()), (name, angle, differing)


def test_agents_outside_the_extent_are_clipped_not_wrapped():
    scene = constant_velocity_scene()
    states = scene.states.copy()
    states[1, :, 0] = 500.0
    raster = rasterize_scene(replace(scene, states=states), UNIT_RASTER)
    assert raster[CHANNEL_INDEX["agents"]].sum() == 0


@pytest.mark.parametrize("rows,cols", [(200, 200), (100, 60)])
def test_configurable_resolution(rows, cols):
    config = RasterConfig(Extent(10.0, 10.0, 10.0, 10.0), rows=rows, cols=cols)
    raster = rasterize_scene(constant_velocity_scene(), config)
    assert raster.shape == (len(CHANNELS), rows, cols)
    # The ego box covers 4 m x 2 m of a 20 m x 20 m extent: 2% of the pixels.
    assert (raster[CHANNEL_INDEX["ego"]] > 0).mean() == pytest.approx(0.02, abs=0.004)
