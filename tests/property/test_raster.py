"""Properties of the BEV raster (rasterize/raster.py) for generated scenes: agents near and
absurdly far, any heading, sizes from centimetres to lorries, histories with invalid (NaN) steps,
lanes, signals and predicted futures. Hand-checked pixels live in tests/rasterize/test_raster.py;
here only what must hold for every scene."""

import warnings
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from rasterize.config import FAMILY_EXTENTS, Extent, RasterConfig
from rasterize.errors import InputError
from rasterize.frames import ego_from_world, pixel_from_ego, world_from_ego
from rasterize.predict import MAX_OFFSET_M, predict_along_lanes
from rasterize.raster import (
    CHANNEL_INDEX,
    FUTURE_DIMMEST,
    STOP_LINE_M,
    channel_index,
    channels,
    history_intensity,
    rasterize_scene,
    red_intensity,
)
from rasterize.scene import Lane, LineType, Scene, Signal
from tests.scenes import UNIT_RASTER, state

PROPERTY = settings(max_examples=100, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])

# Coordinates from the ego's own neighbourhood out to 1e300 m (CommonRoad maps sit at UTM-sized
# offsets; adapters may hand over anything finite).
near = st.one_of(st.floats(-60.0, 60.0), st.floats(-3.0, 3.0))
coordinate = st.one_of(near, st.floats(-1e7, 1e7), st.sampled_from([1e12, -1e12, 1e200, -1e300]))
angle = st.floats(-4 * np.pi, 4 * np.pi)
size = st.one_of(st.tuples(st.floats(0.05, 20.0), st.floats(0.05, 4.0)),
                st.tuples(st.floats(12.0, 25.0), st.floats(2.4, 3.0)))    # lorries


@st.composite
def raster_configs(draw):
    if draw(st.booleans()):
        extent = FAMILY_EXTENTS[draw(st.sampled_from(sorted(FAMILY_EXTENTS)))]
    else:
        extent = Extent(*(draw(st.floats(0.5, 80.0)) for _ in range(4)))
    return RasterConfig(extent, rows=draw(st.integers(2, 48)), cols=draw(st.integers(2, 48)),
                        history_s=draw(st.sampled_from([0.0, 0.5, 1.0, 2.0])),
                        predict_s=draw(st.sampled_from([0.0, 0.0, 1.0, 3.0])))


@st.composite
def lanes(draw, around):
    """A few lanes near `around` (world), straight or bent, any direction."""
    out = []
    for _ in range(draw(st.integers(0, 2))):
        start = np.asarray(around) + [draw(near), draw(near)]
        bends = [draw(st.floats(-0.5, 0.5)) for _ in range(draw(st.integers(1, 4)))]
        turns = np.cumsum([draw(angle), *bends])
        steps = draw(st.floats(2.0, 40.0))
        centre = start + np.concatenate([[[0.0, 0.0]], np.cumsum(
            steps * np.stack([np.cos(turns), np.sin(turns)], axis=1), axis=0)])
        normal = np.stack([-np.sin(turns), np.cos(turns)], axis=1)
        normal = np.concatenate([normal[:1], normal])
        width = draw(st.floats(2.5, 5.0))
        lines = st.sampled_from(list(LineType))
        out.append(Lane(centre, centre + 0.5 * width * normal, centre - 0.5 * width * normal,
                        draw(lines), draw(lines), width, draw(st.floats(0.0, 100.0))))
    return tuple(out)


@st.composite
def scenes(draw, max_agents=4):
    """Scenes whose ego sits anywhere (huge coordinates included) among agents near and far,
    some steps invalid and NaN."""
    n = draw(st.integers(1, max_agents))
    t = draw(st.integers(1, 5))
    now = draw(st.integers(0, t - 1))
    ego = draw(st.integers(0, n - 1))
    dt = draw(st.sampled_from([0.1, 0.5, 1.0]))
    origin = np.array([draw(coordinate), draw(coordinate)])
    states = np.empty((n, t, 6))
    valid = np.empty((n, t), bool)
    for i in range(n):
        far = draw(st.booleans())
        for k in range(t):
            xy = [draw(coordinate), draw(coordinate)] if far else origin + [draw(near), draw(near)]
            states[i, k] = state(*xy, draw(angle), draw(st.floats(0.0, 40.0)), draw(st.floats(-1.0, 1.0)))
            valid[i, k] = draw(st.booleans())
    valid[ego, now] = True
    states[~valid] = np.nan
    sizes = np.array([draw(size) for _ in range(n)])
    signals = ()
    if draw(st.booleans()):
        a = origin + [draw(near), draw(near)]
        signals = (Signal(np.stack([a, a + [draw(near) / 10, draw(near) / 10]]), [0.0, 1.0, 2.0],
                          [draw(st.booleans()) for _ in range(3)]),)
    return Scene(states, valid, sizes, np.zeros(n), ego, now, dt,
                 lanes=draw(lanes(origin)) if np.abs(origin).max() < 1e7 else (), signals=signals)


def _rasterize(scene, config):
    """The raster, with any warning made an error (a NaN or huge value cast to int draws
    garbage) but overflow: squared distances of points 1e200 m away are inf, and rightly so."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", "overflow encountered", RuntimeWarning)
        return rasterize_scene(scene, config)


def _ego_pose(scene):
    return scene.ego_state()[:2], np.arctan2(scene.ego_state()[3], scene.ego_state()[2])


@np.errstate(all="ignore")   # far boxes: inf corners are right
def _box_px(xy, heading_xy, size, pose, config):
    """Pixel corners [4, 2] of a box at world `xy`, computed independently of the rasterizer."""
    fwd = np.asarray(heading_xy) / np.hypot(*heading_xy)
    half_l, half_w = 0.5 * size[0] * fwd, 0.5 * size[1] * np.array([-fwd[1], fwd[0]])
    corners = xy + np.array([half_l + half_w, half_l - half_w, -half_l - half_w, -half_l + half_w])
    return pixel_from_ego(ego_from_world(corners, *pose), config)


@np.errstate(all="ignore")   # far boxes: inf distances are right
def _edge_distance(box, points):
    """Largest signed distance [P] of points to the lines through a convex box's edges (outward
    positive): -depth inside, a lower bound of the distance outside. A box without area (far
    from the world origin, metres vanish in the rounding) is the distance to its outline."""
    a, b = box - box.mean(axis=0), np.roll(box, -1, axis=0) - box.mean(axis=0)
    if abs(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])) < 1e-9:
        edges = np.roll(box, -1, axis=0) - box
        t = np.clip(np.einsum("pkd,kd->pk", points[:, None] - box, edges)
                    / np.maximum((edges ** 2).sum(-1), 1e-300), 0.0, 1.0)
        nearest = box + t[..., None] * edges
        return np.linalg.norm(points[:, None] - nearest, axis=-1).min(axis=1)
    d = np.full(len(points), -np.inf)
    centre = box.mean(axis=0)
    for a, b in zip(box, np.roll(box, -1, axis=0), strict=True):
        edge = b - a
        if np.hypot(*edge) < 1e-9:
            continue
        normal = np.array([edge[1], -edge[0]]) / np.hypot(*edge)
        if normal @ (centre - a) > 0:
            normal = -normal
        d = np.maximum(d, (points - a) @ normal)
    return d


def _pixel_centres(config):
    rows, cols = np.meshgrid(np.arange(config.rows), np.arange(config.cols), indexing="ij")
    return np.stack([cols.ravel() + 0.5, rows.ravel() + 0.5], axis=1)


@PROPERTY
@given(scene=scenes(), config=raster_configs())
def test_raster_has_the_configured_shape_and_channel_values(scene, config):
    raster = _rasterize(scene, config)
    assert raster.shape == (len(channels(config)), config.rows, config.cols)
    assert raster.dtype == np.uint8
    for name in ("ego", "agents"):
        assert set(np.unique(raster[CHANNEL_INDEX[name]])) <= {0, 255}
    ages = np.arange(0, scene.current_index + 1) * scene.dt
    fading = {0} | {history_intensity(a, config.history_s, scene.dt) for a in ages if a > 0}
    for name in ("ego_history", "agents_history"):
        assert set(np.unique(raster[CHANNEL_INDEX[name]])) <= fading
    if config.predict_s > 0:
        future = raster[channel_index(config)["agents_future"]]
        assert ((future == 0) | (future >= FUTURE_DIMMEST)).all()
    # The ego's centre lies inside every extent; a pixel from the edge, it is always drawn
    # (nearer, a box thinner than a pixel may round onto the pixel beyond the edge).
    col, row = pixel_from_ego(np.zeros(2), config)
    if 1 <= col <= config.cols - 1 and 1 <= row <= config.rows - 1:
        assert raster[CHANNEL_INDEX["ego"]].any()


@PROPERTY
@given(scene=scenes(), config=raster_configs())
def test_boxes_cover_the_pixels_whose_centres_they_contain(scene, config):
    """Pixels deeper than 1 px inside a box now are painted, pixels more than 1 px outside
    every box are not (the exact edge is OpenCV's fixed-point rounding)."""
    raster = _rasterize(scene, config)
    centres = _pixel_centres(config)
    pose, now = _ego_pose(scene), scene.current_index
    present = scene.valid[:, now].copy()
    present[scene.ego_index] = False

    def distance_to(boxes):
        distance = np.full(len(centres), np.inf)
        for box in boxes:
            if np.isfinite(box).all():
                distance = np.minimum(distance, _edge_distance(box, centres))
        return distance

    for name, agents in (("ego", [scene.ego_index]), ("agents", np.flatnonzero(present))):
        boxes = [_box_px(scene.states[i, now, :2], scene.states[i, now, 2:4], scene.sizes[i], pose,
                         config) for i in agents]
        _assert_covers(raster[CHANNEL_INDEX[name]], distance_to(boxes), name)
    if config.predict_s > 0:
        # The predicted boxes, from the predictor itself: the raster must draw what it predicts.
        with np.errstate(over="ignore"):
            xy, fwd = predict_along_lanes(scene, config.predict_s)
        boxes = [_box_px(p, f, scene.sizes[i], pose, config)
                 for i in np.flatnonzero(present) for p, f in zip(xy[i], fwd[i], strict=True)]
        _assert_covers(raster[channel_index(config)["agents_future"]], distance_to(boxes),
                       "agents_future")
        # Stop lines: STOP_LINE_M thick along the line, drawn while their light is ever red.
        lines = [sig.stop_line for sig in scene.signals if red_intensity(sig, config.predict_s) > 0]
        boxes = [_box_px(a + 0.5 * (b - a), b - a, (np.hypot(*(b - a)), STOP_LINE_M), pose, config)
                 for a, b in lines]
        _assert_covers(raster[channel_index(config)["signal_red"]], distance_to(boxes), "signal_red")


def _assert_covers(channel, distance, name):
    painted = channel.ravel() > 0
    assert painted[distance < -1.0].all(), f"{name}: a pixel well inside a box is not painted"
    assert not painted[distance > 1.0].any(), f"{name}: a pixel well outside every box is painted"


@st.composite
def far_agents(draw, scene, config):
    """Agents [M, T, 6], sizes [M, 2] whose boxes, now, in the history and as predicted over
    predict_s, all lie beyond one edge of the raster's extent (in the ego frame)."""
    ext, t = config.extent, scene.num_steps
    pose = _ego_pose(scene)
    m = draw(st.integers(1, 3))
    states = np.full((m, t, 6), np.nan)
    valid = np.zeros((m, t), bool)
    sizes = np.array([draw(size) for _ in range(m)])
    for i in range(m):
        side = draw(st.sampled_from(["front", "back", "left", "right"]))
        for k in range(t):
            if not draw(st.booleans()):
                continue
            speed = draw(st.floats(0.0, 40.0))
            # Predictions move a box at most speed x predict_s along its path, after snapping it
            # up to MAX_OFFSET_M onto a lane; then half its diagonal must clear the edge.
            reach = np.hypot(*sizes[i]) / 2 + speed * config.predict_s + MAX_OFFSET_M
            # ... by more than the fill's fixed-point rounding (1/16 px, twice): on a 2 x 2 raster
            # of 120 m pixels a box 3.7 m beyond the front edge rounds onto it and lights row 0.
            reach += 2.0 * max(config.row_m, config.col_m) / 16.0
            beyond = reach + draw(st.one_of(st.floats(1e-3, 50.0), st.floats(50.0, 1e12)))
            along = draw(st.floats(-1.0, 1.0)) * draw(st.sampled_from([10.0, 1e3, 1e9]))
            x, y = {"front": (ext.front_m + beyond, along), "back": (-ext.back_m - beyond, along),
                    "left": (along, ext.left_m + beyond), "right": (along, -ext.right_m - beyond)}[side]
            xy = world_from_ego(np.array([x, y]), *pose)
            states[i, k] = state(*xy, draw(angle), speed, draw(st.floats(-1.0, 1.0)))
            valid[i, k] = True
    return states, valid, sizes


@PROPERTY
@given(data=st.data(), config=raster_configs())
def test_agents_wholly_outside_the_extent_change_nothing(data, config):
    scene = data.draw(scenes())
    # Placing an agent relative to the ego needs the ego's world position to keep metres.
    assume(np.abs(scene.ego_state()[:2]).max() < 1e7)
    states, valid, sizes = data.draw(far_agents(scene, config))
    at = data.draw(st.integers(0, scene.num_agents))      # anywhere in the agent order
    ego = scene.ego_index + len(states) * (at <= scene.ego_index)
    crowded = replace(scene, states=np.insert(scene.states, [at], states, axis=0),
                      valid=np.insert(scene.valid, [at], valid, axis=0),
                      sizes=np.insert(scene.sizes, [at], sizes, axis=0),
                      kinds=np.zeros(scene.num_agents + len(states)), ego_index=ego)
    np.testing.assert_array_equal(_rasterize(crowded, config), _rasterize(scene, config))


@PROPERTY
@given(scene=scenes(), config=raster_configs(), seed=st.integers(0, 2**16))
def test_agent_order_does_not_matter(scene, config, seed):
    order = np.random.default_rng(seed).permutation(scene.num_agents)
    shuffled = replace(scene, states=scene.states[order], valid=scene.valid[order],
                       sizes=scene.sizes[order], kinds=scene.kinds[order],
                       ego_index=int(np.flatnonzero(order == scene.ego_index)[0]))
    np.testing.assert_array_equal(_rasterize(shuffled, config), _rasterize(scene, config))


@PROPERTY
@given(scene=scenes(), config=raster_configs(), junk=st.one_of(coordinate, st.just(np.nan)),
       junk_size=st.sampled_from([np.nan, -1.0, 0.0, 3.0]))
def test_invalid_steps_and_absent_agents_draw_nothing(scene, config, junk, junk_size):
    """Invalid steps may hold anything (NaN in recordings); an agent absent throughout may have
    any size (Scene's docstring and checks)."""
    states = scene.states.copy()
    states[~scene.valid] = junk
    absent = np.full((1, scene.num_steps, 6), junk)
    with_absent = replace(scene, states=np.concatenate([states, absent]),
                          valid=np.concatenate([scene.valid, np.zeros((1, scene.num_steps), bool)]),
                          sizes=np.concatenate([scene.sizes, [[junk_size, junk_size]]]),
                          kinds=np.zeros(scene.num_agents + 1))
    np.testing.assert_array_equal(_rasterize(with_absent, config), _rasterize(scene, config))


@PROPERTY
@given(scene=scenes(), bad=st.sampled_from([np.nan, np.inf, -np.inf]))
def test_a_valid_step_that_is_not_finite_is_refused(scene, bad):
    states = scene.states.copy()
    states[scene.ego_index, scene.current_index, 0] = bad
    with pytest.raises(InputError, match="non-finite"):
        replace(scene, states=states)


@PROPERTY
@given(data=st.data(), extent=st.tuples(*[st.floats(0.5, 10.0)] * 4), rows=st.integers(2, 24),
       cols=st.integers(2, 24), predict_s=st.sampled_from([0.5, 2.0]))
def test_a_standing_agent_is_predicted_where_it_stands(data, extent, rows, cols, predict_s):
    """Without lanes an agent at speed 0 stays put, so the future channel paints exactly the
    pixels of the agents channel: small rasters among cars and lorries, some over a corner."""
    config = RasterConfig(Extent(*extent), rows=rows, cols=cols, predict_s=predict_s)
    n = data.draw(st.integers(1, 3))
    origin = np.array([data.draw(st.floats(-1e6, 1e6)), data.draw(st.floats(-1e6, 1e6))])
    ego_heading = data.draw(angle)
    offsets = np.array([[data.draw(st.floats(-15.0, 15.0)) for _ in range(2)] for _ in range(n)])
    xy = world_from_ego(offsets, origin, ego_heading)
    states = np.array([[state(*origin, ego_heading)]] + [[state(*p, data.draw(angle))] for p in xy])
    sizes = np.array([[4.5, 1.8]] + [data.draw(size) for _ in range(n)])
    scene = Scene(states, np.ones((n + 1, 1), bool), sizes, np.zeros(n + 1), 0, 0, 0.5)
    raster = _rasterize(scene, config)
    np.testing.assert_array_equal(raster[channel_index(config)["agents_future"]] > 0,
                                  raster[CHANNEL_INDEX["agents"]] > 0)


def _assert_future_matches_now(scene, config):
    raster = _rasterize(scene, config)
    np.testing.assert_array_equal(raster[channel_index(config)["agents_future"]] > 0,
                                  raster[CHANNEL_INDEX["agents"]] > 0)
    assert raster[CHANNEL_INDEX["agents"]].any()


def test_a_lorry_across_a_corner_of_the_raster_is_predicted_there_too():
    """Found by the property above: predicted boxes were culled unless a corner came within 2 px
    of the raster, so a standing 18 m lorry across the raster's front-left corner (every corner
    off the raster) was drawn now but not in agents_future. Culling is by bounding box now."""
    states = np.array([[state(0.0, 0.0, 0.0)], [state(9.0, 9.0, -np.pi / 4)]])
    scene = Scene(states, np.ones((2, 1), bool), np.array([[4.0, 2.0], [18.0, 2.6]]), np.zeros(2),
                  0, 0, 0.5)
    _assert_future_matches_now(scene, replace(UNIT_RASTER, predict_s=1.0))
    # the property's own shrunk example: a 4 m car over a 1 m x 2 m raster
    scene = Scene(np.array([[state(0.0, 0.0, 0.0)], [state(0.0, 0.0, 0.0)]]), np.ones((2, 1), bool),
                  np.array([[4.5, 1.8], [4.0, 1.0]]), np.zeros(2), 0, 0, 0.5)
    _assert_future_matches_now(scene, RasterConfig(Extent(0.5, 0.5, 1.0, 1.0), 2, 2, predict_s=0.5))


def test_a_stop_line_across_the_whole_raster_is_drawn():
    """Same culling for stop lines: a red stop line crossing the raster with both ends off it
    was dropped."""
    signal = Signal(np.array([[3.5, -15.0], [3.5, 15.0]]), [0.0], [True])
    scene = Scene(np.array([[state(0.0, 0.0, 0.0)]]), [[True]], [[4.0, 2.0]], [0], 0, 0, 0.5,
                  signals=(signal,))
    config = replace(UNIT_RASTER, predict_s=1.0)
    expected = np.zeros((20, 20), np.uint8)
    expected[6] = 255                                   # x in [3, 4]: row 6, every column
    np.testing.assert_array_equal(_rasterize(scene, config)[channel_index(config)["signal_red"]],
                                  expected)


def test_agents_far_beyond_int32_pixels_raise_no_cast_warning():
    """An agent 1e12 m away predicted over the next second: its off-raster boxes used to be cast
    to int32 vertices all the same (garbage, and a RuntimeWarning), though never drawn."""
    states = np.array([[state(0.0, 0.0, 0.0)], [state(0.0, 1e12, 0.0)]])
    scene = Scene(states, np.ones((2, 1), bool), np.ones((2, 2)), np.zeros(2), 0, 0, 0.1)
    config = replace(UNIT_RASTER, predict_s=1.0)
    alone = replace(scene, states=states[:1], valid=[[True]], sizes=np.ones((1, 2)), kinds=[0])
    np.testing.assert_array_equal(_rasterize(scene, config), _rasterize(alone, config))
