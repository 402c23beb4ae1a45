from dataclasses import replace

import numpy as np
import pytest

from rasterize.config import Extent, RasterConfig
from rasterize.errors import InputError
from rasterize.frames import ego_from_world, pixel_from_ego
from rasterize.predict import prediction_times
from rasterize.raster import (
    CHANNEL_INDEX,
    CHANNELS,
    channel_index,
    channels,
    future_intensity,
    history_intensity,
    rasterize_scene,
)
from rasterize.scene import Lane, LineType, Signal
from tests.rasterize.test_predict import arc_lane
from tests.scenes import UNIT_RASTER, constant_velocity_scene, state, straight_lane

PREDICT_1S = replace(UNIT_RASTER, predict_s=1.0)
FUTURE = channel_index(PREDICT_1S)["agents_future"]
RED = channel_index(PREDICT_1S)["signal_red"]


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


# --- predicted future (predict_s > 0) ---------------------------------------------------------


def test_predict_s_adds_two_channels_after_the_eight():
    scene = constant_velocity_scene()
    assert channels(UNIT_RASTER) == CHANNELS and len(CHANNELS) == 8
    assert channels(PREDICT_1S) == CHANNELS + ("agents_future", "signal_red")
    assert rasterize_scene(scene, UNIT_RASTER).shape == (8, 20, 20)
    raster = rasterize_scene(scene, PREDICT_1S)
    assert raster.shape == (10, 20, 20)
    # The base channels are drawn exactly as without prediction.
    np.testing.assert_array_equal(raster[:8], rasterize_scene(scene, UNIT_RASTER))


def test_a_config_saved_without_predict_s_loads_as_none_drawn():
    saved = UNIT_RASTER.to_dict()
    del saved["predict_s"]
    config = RasterConfig.from_dict(saved)
    assert config.predict_s == 0.0 and config == UNIT_RASTER
    assert rasterize_scene(constant_velocity_scene(), config).shape[0] == 8


@pytest.mark.parametrize("bad", [-0.5, 10.5, float("nan"), float("inf"), "3", True])
def test_predict_s_is_validated(bad):
    with pytest.raises(InputError, match="predict_s"):
        replace(UNIT_RASTER, predict_s=bad)


def test_future_intensity_fades_from_255_to_64():
    values = future_intensity(prediction_times(3.0), 3.0)
    assert values[0] == 255 and values[-1] == 64 and (np.diff(values) < 0).all()
    assert future_intensity(np.array([1.0]), 1.0)[0] == 64
    assert future_intensity(np.array([0.5]), 0.5)[0] == 255


def test_straight_lane_future_boxes_lie_ahead_along_the_lane():
    # Agent on the lane 6 m to the ego's right (y = -6), at x = -8 heading east at 4 m/s, turned
    # 20 deg towards the ego: along its lane it is at x = -6 (0.5 s) and x = -4 (1 s), on y = -6.
    scene = constant_velocity_scene(lanes=[straight_lane(-6.0)])
    states = scene.states.copy()
    states[1, :] = state(-8.0, -6.0, np.deg2rad(20), 4.0)
    raster = rasterize_scene(replace(scene, states=states), PREDICT_1S)
    expected = np.zeros((20, 20), np.uint8)
    # 0.5 s: x in [-8, -4] -> rows 14..17; 1 s: x in [-6, -2] -> rows 12..15; y in [-7, -5] ->
    # cols 15..16. The sooner box is the brighter and wins where they overlap.
    expected[12:16, 15:17] = 64
    expected[14:18, 15:17] = 255
    np.testing.assert_array_equal(raster[FUTURE], expected)
    assert raster[RED].sum() == 0


def test_curved_lane_future_boxes_follow_the_curve():
    config = RasterConfig(Extent(30.0, 30.0, 30.0, 30.0), rows=60, cols=60, history_s=1.0,
                          predict_s=3.0)
    lane = arc_lane((10.0, -15.0), 10.0, -np.pi / 2, np.pi / 2)
    scene = constant_velocity_scene(lanes=[lane])
    states = scene.states.copy()
    states[1, :] = state(10.0, -25.0, 0.0, 8.0)       # bottom of the circle, heading east
    raster = rasterize_scene(replace(scene, states=states), config)[channel_index(config)["agents_future"]]
    times = prediction_times(3.0)
    theta = -np.pi / 2 + 8.0 * times / 10.0
    on_curve = np.array([10.0, -15.0]) + 10.0 * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    col, row = np.floor(pixel_from_ego(ego_from_world(on_curve, np.zeros(2), 0.0), config)).astype(int).T
    # Boxes 4 m apart along the arc: each centre pixel shows its own box's brightness.
    np.testing.assert_array_equal(raster[row, col], future_intensity(times, 3.0))
    # Straight on at the heading it would be at (34, -25) after 3 s: nothing drawn there.
    straight = pixel_from_ego(ego_from_world(np.array([[28.0, -25.0]]), np.zeros(2), 0.0), config)
    c, r = np.floor(straight[0]).astype(int)
    assert raster[r - 2:r + 3, c - 2:c + 3].sum() == 0


def test_the_ego_is_not_drawn_in_the_future_channel():
    # The ego drives east at 2 m/s; the agent stands still, so its future is its present box.
    raster = rasterize_scene(constant_velocity_scene(ego_speed=2.0), PREDICT_1S)
    np.testing.assert_array_equal(raster[FUTURE] > 0, raster[CHANNEL_INDEX["agents"]] > 0)


def test_the_recorded_future_is_not_drawn():
    scene = constant_velocity_scene(lanes=[straight_lane(-6.0)])
    states = scene.states.copy()
    states[1, :] = state(-8.0, -6.0, 0.0, 4.0)
    calm = replace(scene, states=states)
    wild_states = states.copy()
    wild_states[:, calm.current_index + 1:] = state(3.0, 7.0, 1.0, 9.0, 0.5)
    wild = replace(calm, states=wild_states)
    base = rasterize_scene(calm, PREDICT_1S)
    assert base[FUTURE].any()
    np.testing.assert_array_equal(rasterize_scene(wild, PREDICT_1S), base)
    np.testing.assert_array_equal(rasterize_scene(calm.past(), PREDICT_1S), base)


def _signal_scene(times, red):
    # Stop line across x = 3.5, y in [-2, 2]: drawn 1 m thick -> row 6, cols 8..11.
    signal = Signal(np.array([[3.5, -2.0], [3.5, 2.0]]), np.array(times, float), np.array(red))
    return replace(constant_velocity_scene(), signals=(signal,))


@pytest.mark.parametrize("times,red,value", [
    ([0.0], [True], 255),                       # red throughout
    ([0.0], [False], 0),                        # green throughout: not drawn
    ([0.0, 1.0], [True, False], 102),           # red at 0, 0.5 of 0..2 s: 2 of 5 samples
    ([0.0, 1.5], [False, True], 102),           # green now, red at 1.5, 2 s
    ([0.0, 0.4, 5.0], [False, True, False], 204),   # red from 0.4 s to past the horizon
])
def test_signal_red_is_the_share_of_the_horizon_the_light_is_red(times, red, value):
    config = replace(UNIT_RASTER, predict_s=2.0)
    raster = rasterize_scene(_signal_scene(times, red), config)[channel_index(config)["signal_red"]]
    expected = np.zeros((20, 20), np.uint8)
    expected[6, 8:12] = value
    np.testing.assert_array_equal(raster, expected)


def test_signals_draw_nothing_without_predict_s():
    raster = rasterize_scene(_signal_scene([0.0], [True]), UNIT_RASTER)
    np.testing.assert_array_equal(raster, rasterize_scene(constant_velocity_scene(), UNIT_RASTER))


def test_invalid_steps_draw_nothing_whatever_their_states_hold():
    """States of invalid steps (NaN in recordings) are never drawn and raise no cast warning."""
    import warnings

    from rasterize.raster import rasterize_scene
    from tests.scenes import UNIT_RASTER, constant_velocity_scene, straight_lane

    with_nan = constant_velocity_scene(lanes=[straight_lane(0.0)])
    with_junk = constant_velocity_scene(lanes=[straight_lane(0.0)])
    for scene, fill in ((with_nan, np.nan), (with_junk, 3.0)):
        scene.states[1, :2] = fill
        scene.valid[1, :2] = False
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a = rasterize_scene(with_nan, UNIT_RASTER)
    np.testing.assert_array_equal(a, rasterize_scene(with_junk, UNIT_RASTER))
