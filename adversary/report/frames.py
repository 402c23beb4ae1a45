"""A job's episode as pictures, from the npz artifact the job leaves
(adversary.attacks.episode.artifact_of): the BEV at each recorded step, with the risk map of the
plan in force beside it where the planner makes one. They make the report's frame strips, its
risk maps over time and its animated GIFs.

Drawn with numpy, OpenCV (the rasteriser) and Pillow rather than matplotlib: a report draws them
for every job, and a frame costs milliseconds this way.

An artifact holds the final scene with up to 8 s of history at the recording's rate (0.1 s;
stores written before that hold 0.5 s steps, which are read the same way), the last plan, and the
risk map of every plan with its time (`plans__`; older stores only the last plan's). A crash
attack's artifact holds its own panel PNG (`crash_panel_png`) and its final drive the same way
(its whole 8 s; crash stores written before that hold the panel only).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from adversary.attacks.recorded import job_raster
from rasterize.config import RasterConfig
from rasterize.frames import box_corners, ego_from_world, ego_pose, pixel_from_ego
from rasterize.raster import rasterize_scene
from rasterize.scene import Scene
from rasterize.scene_io import unpack_scene
from riskmap.figures.panels import raster_to_rgb
from riskmap.infra.atomic import atomic_write

TILE = 176                 # pixels of a BEV or risk-map tile (square, as the planner sees it)
TRAIL_DT_S = 0.5           # the BEV's fading history boxes every 0.5 s, as the planner's raster
STRIP_SPAN_S = 3.0         # the strip shows the last 3 s (all of a shorter episode)
STRIP_SLOTS = 4
RISK_LEVELS = 32          # colours of a risk map (fewer: smaller GIFs, no dithering noise)
RISK_PANELS = 5            # plans shown in the risk map over time
GIF_FPS = 5                # frames per second of the animation (the 10 Hz recording thinned)
GIF_MAX_FRAMES = 40        # the last 8 s at 5 fps
GIF_HOLD_LAST_MS = 1500    # the last frame (the collision) stays this long
GIF_TILE = 168             # smaller than the strip's: GIFs stay well under 1 MB

_EGO, _ADVERSARY = (242, 38, 25), (255, 159, 28)
_PAGE, _INK, _MUTED = (255, 255, 255), (34, 34, 34), (110, 110, 110)


@dataclass
class JobArtifact:
    """What one job's artifact holds (any part may be missing)."""

    final: Scene | None = None              # the last recorded step with up to 8 s of history
    adversary_index: int = -1               # the adversary's agent index in `final`, -1: none
    plan_scene: Scene | None = None         # the scene of the last plan
    plan: dict = field(default_factory=dict)   # the last plan's arrays (waypoints, risk_map, svf)
    risk_times_s: np.ndarray | None = None  # [P] the time of each plan with a risk map
    risk_maps: np.ndarray | None = None     # [P, G, G]
    crash_panel_png: bytes | None = None    # a crash attack's own panel

    @property
    def has_frames(self) -> bool:
        return self.final is not None


def _prefixed(arrays: dict, prefix: str) -> dict:
    return {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}


def load_artifact(path: Path) -> JobArtifact:
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    art = JobArtifact()
    if "crash_panel_png" in arrays:
        art.crash_panel_png = arrays["crash_panel_png"].tobytes()
    if "final__states" in arrays:
        art.final = unpack_scene(_prefixed(arrays, "final__"), 0)
        art.adversary_index = int(arrays.get("adversary_index", -1))
    if "plan_scene__states" in arrays:
        art.plan_scene = unpack_scene(_prefixed(arrays, "plan_scene__"), 0)
        art.plan = _prefixed(arrays, "plan__")
    if "plans__risk_map" in arrays:
        art.risk_times_s = arrays["plans__time_s"].astype(np.float64)
        art.risk_maps = arrays["plans__risk_map"].astype(np.float32)
    elif "risk_map" in art.plan and art.plan_scene is not None:      # older stores: the last plan
        art.risk_times_s = np.array([art.plan_scene.time_s], np.float64)
        art.risk_maps = art.plan["risk_map"][None].astype(np.float32)
    return art


# --------------------------------------------------------------------------------- scenes
def recorded_indices(final: Scene) -> np.ndarray:
    """Time indices of `final` at which the ego was recorded (the episode's span in the window)."""
    valid = final.valid[final.ego_index, :final.current_index + 1]
    first = int(np.argmax(valid))
    return np.arange(first, final.current_index + 1)


def time_at(final: Scene, index: int) -> float:
    return float(final.time_s) - (final.current_index - index) * final.dt


def scene_at(final: Scene, index: int, history_s: float) -> Scene:
    """The scene at time index `index` of `final`, its past thinned to TRAIL_DT_S steps (so that
    the raster's fading boxes are those the planner sees)."""
    stride = max(1, round(TRAIL_DT_S / final.dt))
    keep = np.arange(index % stride, index + 1, stride)[-(round(history_s / TRAIL_DT_S) + 1):]
    return replace(final, states=final.states[:, keep], valid=final.valid[:, keep],
                   current_index=len(keep) - 1, dt=stride * final.dt, time_s=time_at(final, index))


# --------------------------------------------------------------------------------- tiles
def _raster(env_id: str, size: int) -> RasterConfig:
    return job_raster(env_id, size, size)


def bev_tile(scene: Scene, raster: RasterConfig, adversary: int = -1) -> np.ndarray:
    """uint8 [rows, cols, 3]: the BEV raster in colour, the adversary's box outlined in orange."""
    rgb = np.clip(np.rint(raster_to_rgb(rasterize_scene(scene, raster)) * 255), 0, 255).astype(np.uint8)
    if 0 <= adversary < scene.num_agents and scene.valid[adversary, scene.current_index]:
        from PIL import Image, ImageDraw

        origin, heading = ego_pose(scene)
        s = scene.states[adversary, scene.current_index]
        corners = box_corners(s[:2], s[2:4], *scene.sizes[adversary])
        px = pixel_from_ego(ego_from_world(corners, origin, heading), raster)
        image = Image.fromarray(rgb)
        ImageDraw.Draw(image).polygon([tuple(p) for p in px], outline=_ADVERSARY, width=2)
        rgb = np.asarray(image)
    return rgb


def risk_limits(maps: np.ndarray) -> tuple[float, float]:
    finite = maps[np.isfinite(maps)]
    if finite.size == 0:
        return 0.0, 1.0
    lo, hi = float(np.percentile(finite, 1)), float(finite.max())
    return (lo, hi) if hi > lo else (lo - 1.0, hi + 1.0)


def risk_tile(risk: np.ndarray, limits: tuple[float, float], size: int, ego_row: float) -> np.ndarray:
    """uint8 [size, size, 3]: the risk map coloured with magma (dark: costly), the ego marked."""
    from matplotlib import colormaps
    from PIL import Image, ImageDraw

    lo, hi = limits
    x = np.clip((np.nan_to_num(risk, nan=lo, neginf=lo, posinf=hi) - lo) / (hi - lo), 0.0, 1.0)
    x = np.round(x * (RISK_LEVELS - 1)) / (RISK_LEVELS - 1)
    rgb = colormaps["magma"](x, bytes=True)[..., :3]
    image = Image.fromarray(rgb).resize((size, size), Image.NEAREST)
    cx, cy = size / 2, ego_row * size
    ImageDraw.Draw(image).rectangle([cx - 3, cy - 6, cx + 3, cy + 6], outline=(80, 220, 255), width=2)
    return np.asarray(image)


def colour_bar(width: int) -> np.ndarray:
    """uint8 [10, width, 3]: the risk tiles' colour ramp, low values on the left."""
    from matplotlib import colormaps

    x = np.round(np.linspace(0, 1, width) * (RISK_LEVELS - 1)) / (RISK_LEVELS - 1)
    ramp = colormaps["magma"](x, bytes=True)[None, :, :3]
    return np.repeat(ramp, 10, axis=0)


def _ego_row(raster: RasterConfig) -> float:
    """The ego's row as a fraction of the height (the risk grid covers the raster's extent)."""
    return raster.extent.front_m / raster.extent.length_m


def risk_map_at(art: JobArtifact, t_s: float) -> tuple[np.ndarray, float] | None:
    """The risk map of the plan in force at `t_s` (the last one made by then) and its time."""
    if art.risk_maps is None:
        return None
    made = np.flatnonzero(art.risk_times_s <= t_s + 1e-3)
    if made.size == 0:
        return None
    return art.risk_maps[made[-1]], float(art.risk_times_s[made[-1]])


# --------------------------------------------------------------------------------- layout
def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:          # Pillow without FreeType: a fixed bitmap font
        return ImageFont.load_default()


def _wrap(text: str, font, width: int) -> list[str]:
    """`text` in lines no wider than `width` pixels (words are not split)."""
    lines, line = [], ""
    for word in text.split(" "):
        candidate = f"{line} {word}" if line else word
        if line and font.getlength(candidate) > width:
            lines.append(line)
            line = word
        else:
            line = candidate
    return lines + [line]


def compose(rows: list[list[tuple[np.ndarray | None, str]]], header: list[tuple[str, tuple]],
            footer: str = "", bar: tuple[tuple[float, float], str] | None = None,
            tile: int = TILE):
    """A white PIL image: header lines (wrapped to the width), then rows of titled tiles (None:
    an empty grey tile, its title saying why), an optional colour bar (limits, label) and a
    footer line."""
    from PIL import Image, ImageDraw

    pad, title_h, line_h = 6, 17, 18
    small, big = _font(12), _font(14)
    cols = max(len(r) for r in rows)
    width = pad + cols * (tile + pad)
    lines = [(line, colour) for text, colour in header for line in _wrap(text, big, width - 2 * pad)]
    footer_lines = _wrap(footer, small, width - 2 * pad) if footer else []
    height = pad + line_h * len(lines) + len(rows) * (title_h + tile + pad)
    height += (30 if bar else 0) + line_h * len(footer_lines) + pad
    page = Image.new("RGB", (width, height), _PAGE)
    draw = ImageDraw.Draw(page)
    y = pad
    for text, colour in lines:
        draw.text((pad, y), text, fill=colour, font=big)
        y += line_h
    for row in rows:
        for i, (image, title) in enumerate(row):
            x = pad + i * (tile + pad)
            draw.text((x, y), title, fill=_INK if image is not None else _MUTED, font=small)
            if image is None:
                draw.rectangle([x, y + title_h, x + tile - 1, y + title_h + tile - 1], fill=(241, 243, 245))
            else:
                page.paste(Image.fromarray(image), (x, y + title_h))
        y += title_h + tile + pad
    if bar:
        (lo, hi), label = bar
        bar_w = min(width - 2 * pad, 2 * tile)
        page.paste(Image.fromarray(colour_bar(bar_w)), (pad, y))
        draw.text((pad, y + 12), f"{lo:.1f}", fill=_INK, font=small)
        draw.text((pad + bar_w - small.getlength(f"{hi:.1f}"), y + 12), f"{hi:.1f}", fill=_INK, font=small)
        draw.text((pad + bar_w + 8, y), label, fill=_INK, font=small)
        y += 30
    for line in footer_lines:
        draw.text((pad, y), line, fill=_MUTED, font=small)
        y += line_h
    return page


def _t(t_s: float) -> str:
    """A time for a label, without the "-0.0" that float32 arithmetic leaves."""
    return f"{round(t_s, 1) + 0.0:.1f}"


def _stretch_note(raster: RasterConfig) -> str:
    ext = raster.extent
    stretch = (ext.length_m / raster.rows) / (ext.width_m / raster.cols)
    note = f"{ext.length_m:.0f} m ahead/behind x {ext.width_m:.0f} m across"
    return note + (f", lateral axis stretched x{stretch:.0f}" if stretch > 1.5 else "")


# --------------------------------------------------------------------------------- pictures
def strip_indices(final: Scene) -> np.ndarray:
    """Up to STRIP_SLOTS distinct recorded indices, evenly over the last STRIP_SPAN_S seconds
    (over the whole episode when it was shorter), the last recorded step included."""
    recorded = recorded_indices(final)
    span = min(round(STRIP_SPAN_S / final.dt), len(recorded) - 1)
    picks = np.rint(np.linspace(recorded[-1] - span, recorded[-1], STRIP_SLOTS)).astype(int)
    return np.unique(picks)


def strip_image(art: JobArtifact, env_id: str, title: str):
    """The frame strip: the BEV at up to four times of the episode's last seconds; None without
    a recorded scene."""
    if not art.has_frames:
        return None
    final, raster = art.final, _raster(env_id, TILE)
    end = time_at(final, final.current_index)
    tiles = []
    for index in strip_indices(final):
        t = time_at(final, index)
        label = f"t = {_t(t)} s" + (" (end)" if index == final.current_index else f" (end - {_t(end - t)} s)")
        tiles.append((bev_tile(scene_at(final, index, raster.history_s), raster, art.adversary_index), label))
    legend = "ego red, other vehicles blue (fading: their last 2 s), adversary outlined orange"
    return compose([tiles], [(title, _INK), (legend, _MUTED)], footer=_stretch_note(raster))


def risk_over_time_image(art: JobArtifact, env_id: str, title: str):
    """Up to RISK_PANELS plans spread over the episode: the BEV when the plan was made (top) and
    its risk map (below), one colour scale; None where the planner made no risk map."""
    if art.risk_maps is None or len(art.risk_maps) == 0:
        return None
    raster = _raster(env_id, TILE)
    picks = np.unique(np.rint(np.linspace(0, len(art.risk_maps) - 1,
                                          min(RISK_PANELS, len(art.risk_maps)))).astype(int))
    limits = risk_limits(art.risk_maps)
    bevs, maps = [], []
    for p in picks:
        t = float(art.risk_times_s[p])
        bev = None
        if art.has_frames:
            final = art.final
            index = final.current_index - round((time_at(final, final.current_index) - t) / final.dt)
            if recorded_indices(final)[0] <= index <= final.current_index:
                bev = bev_tile(scene_at(final, index, raster.history_s), raster, art.adversary_index)
        bevs.append((bev, f"BEV, t = {_t(t)} s" if bev is not None else f"t = {_t(t)} s: before the stored 8 s"))
        maps.append((risk_tile(art.risk_maps[p], limits, TILE, _ego_row(raster)),
                     f"risk map of the plan at t = {_t(t)} s"))
    legend = f"{len(art.risk_maps)} plans; {len(picks)} shown, ego at the cyan box"
    return compose([bevs, maps], [(title, _INK), (legend, _MUTED)],
                   bar=(limits, "reward (<= 0): dark = costly"), footer=_stretch_note(raster))


def animation_frames(art: JobArtifact, env_id: str, title: str, collision_time_s: float | None
                     ) -> tuple[list[np.ndarray], list[int]]:
    """(RGB frames, durations in ms): the BEV at GIF_FPS (or the recording's rate, if slower)
    over the last GIF_MAX_FRAMES steps, the risk map of the plan in force beside it where the
    planner makes one; the last frame held. Empty without a recorded scene."""
    if not art.has_frames:
        return [], []
    final, raster = art.final, _raster(env_id, GIF_TILE)
    stride = max(1, round(1.0 / (GIF_FPS * final.dt)))
    recorded = recorded_indices(final)
    indices = recorded[::-1][::stride][::-1][-GIF_MAX_FRAMES:]   # ends at the last step
    limits = risk_limits(art.risk_maps) if art.risk_maps is not None else None
    frames = []
    for index in indices:
        t = time_at(final, index)
        tiles = [(bev_tile(scene_at(final, index, raster.history_s), raster, art.adversary_index), "BEV")]
        if limits is not None:
            current = risk_map_at(art, t)
            tiles.append((None, "risk map: no plan yet") if current is None else
                         (risk_tile(current[0], limits, GIF_TILE, _ego_row(raster)),
                          f"risk map (plan at {_t(current[1])} s)"))
        crashed = collision_time_s is not None and t >= collision_time_s - 0.5 * final.dt
        status = (f"t = {_t(t)} s   COLLISION", _EGO) if crashed else (f"t = {_t(t)} s", _INK)
        frames.append(np.asarray(compose([tiles], [status, (title, _MUTED)], tile=GIF_TILE)))
    durations = [round(1000 * stride * final.dt)] * len(frames)
    durations[-1] = max(durations[-1], GIF_HOLD_LAST_MS)
    return frames, durations


def write_gif(frames: list[np.ndarray], durations: list[int], path: Path) -> Path:
    """An endlessly looping GIF (imageio) of equally sized RGB frames, written atomically."""
    import imageio.v3 as iio

    data = iio.imwrite("<bytes>", np.stack(frames), extension=".gif", duration=durations, loop=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda f: f.write(data))
    return path


def gif_frame_count(path: Path) -> int:
    from PIL import Image

    with Image.open(path) as image:
        return int(getattr(image, "n_frames", 1))
