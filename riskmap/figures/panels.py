"""PNG figures of scenes: the BEV raster as a colour picture with the future path on top."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rasterize.config import RasterConfig
from rasterize.frames import ego_from_world, ego_pose
from rasterize.raster import CHANNELS, FUTURE_CHANNELS, rasterize_scene
from rasterize.scene import Scene

# Colours (RGB in [0, 1]) of the raster layers, painted in this order; the predicted-future
# layers (rasters drawn with predict_s > 0) go under the present boxes.
_PALETTE = (
    ("drivable", (0.36, 0.38, 0.42)),
    ("lane_centre", (0.45, 0.60, 0.80)),
    ("lane_dashed", (0.92, 0.92, 0.92)),
    ("lane_solid", (1.00, 1.00, 1.00)),
    ("signal_red", (1.00, 0.10, 0.10)),
    ("agents_future", (0.75, 0.45, 1.00)),
    ("agents_history", (0.30, 0.55, 1.00)),
    ("ego_history", (1.00, 0.45, 0.35)),
    ("agents", (0.15, 0.45, 1.00)),
    ("ego", (0.95, 0.15, 0.10)),
)
_BACKGROUND = (0.10, 0.11, 0.12)


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def raster_to_rgb(raster: np.ndarray) -> np.ndarray:
    """uint8 [C, H, W] raster into an RGB float image [H, W, 3]: each layer alpha-blended on top.
    C is 8 (`CHANNELS`) or 10 (with `FUTURE_CHANNELS`)."""
    rgb = np.broadcast_to(np.array(_BACKGROUND), raster.shape[1:] + (3,)).copy()
    index = {name: i for i, name in enumerate(CHANNELS + FUTURE_CHANNELS[:len(raster) - len(CHANNELS)])}
    for name, colour in _PALETTE:
        if name not in index:
            continue
        alpha = raster[index[name]].astype(np.float64)[..., None] / 255.0
        rgb = rgb * (1 - alpha) + np.array(colour) * alpha
    return rgb


def save_plan_png(scene: Scene, plan, config: RasterConfig, path: Path, title: str = "") -> Path:
    """A closed-loop frame: the scene with the plan's 12 waypoints on top (the scene alone where
    `plan` is None: an ego that drives itself)."""
    return save_scene_png(scene, config, path, title,
                          plan_waypoints=None if plan is None else plan.waypoints)


def save_scene_png(scene: Scene, config: RasterConfig, path: Path, title: str = "",
                   plan_waypoints: np.ndarray | None = None) -> Path:
    """Write the scene's raster with the ego's recorded future (if any) overlaid, labelled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    ext = config.extent
    fig, ax = plt.subplots(figsize=(6.2, 6.4), dpi=110)
    ax.imshow(raster_to_rgb(rasterize_scene(scene, config)), interpolation="nearest",
              extent=(ext.left_m, -ext.right_m, -ext.back_m, ext.front_m), aspect="auto")
    shown = CHANNELS + (FUTURE_CHANNELS if config.predict_s > 0 else ())
    handles = [Patch(color=c, label=n.replace("_", " ")) for n, c in _PALETTE
               if n != "lane_centre" and n in shown]
    if scene.num_future_steps and scene.valid[scene.ego_index, scene.current_index + 1:].all():
        origin, heading = ego_pose(scene)
        future = ego_from_world(scene.ego_future_xy(), origin, heading)
        path_xy = np.concatenate([[[0.0, 0.0]], future])
        ax.plot(path_xy[:, 1], path_xy[:, 0], "-", color="#3ddc84", lw=1.6)
        ax.plot(future[:, 1], future[:, 0], "o", color="#3ddc84", ms=3.5)
        handles.append(Line2D([], [], color="#3ddc84", marker="o", ms=3.5,
                              label=f"future {scene.num_future_steps * scene.dt:.0f} s"))
    if scene.route_xy is not None:
        origin, heading = ego_pose(scene)
        route = ego_from_world(scene.route_xy, origin, heading)
        ax.plot(route[:, 1], route[:, 0], "--", color="#ffd43b", lw=1.2)
        ax.plot(route[-1, 1], route[-1, 0], "*", color="#ffd43b", ms=11, mec="black", mew=0.5)
        handles.append(Line2D([], [], color="#ffd43b", ls="--", marker="*", ms=8,
                              label="route to goal"))
    if plan_waypoints is not None:
        path_xy = np.concatenate([[[0.0, 0.0]], plan_waypoints])
        ax.plot(path_xy[:, 1], path_xy[:, 0], "-o", color="#ff66ff", lw=1.4, ms=3)
        handles.append(Line2D([], [], color="#ff66ff", marker="o", ms=3, label="plan 6 s"))
    ax.set_xlim(ext.left_m, -ext.right_m)
    ax.set_ylim(-ext.back_m, ext.front_m)
    ax.set_xlabel("lateral y (m, + left of ego)")
    ax.set_ylabel("forward x (m)")
    stretch = (ext.length_m / config.rows) / (ext.width_m / config.cols)
    note = f"  [lateral axis stretched x{stretch:.1f}]" if stretch > 1.5 else ""
    speed = scene.ego_state()[4]
    ax.set_title((title + "\n" if title else "") + f"ego {speed:.1f} m/s, "
                 f"{int(scene.valid[:, scene.current_index].sum()) - 1} other agents{note}",
                 fontsize=9)
    ax.legend(handles=handles, loc="upper right", fontsize=6.5, framealpha=0.8)
    return _save(fig, path)


def scene_figures(data: Path, out: Path, count: int) -> list[Path]:
    """PNGs of `count` windows spread evenly over a dataset."""
    from riskmap.data.dataset import DemoDataset

    dataset = DemoDataset(data)
    picks = np.unique(np.linspace(0, len(dataset) - 1, min(count, len(dataset))).astype(int))
    paths = []
    for i in picks:
        scene = dataset.scene(int(i))
        title = f"{dataset.source}  window {i}  t = {scene.time_s:.1f} s"
        paths.append(save_scene_png(scene, dataset.raster_config, Path(out) / f"scene_{i:05d}.png",
                                    title))
    return paths


def save_plan_panels(scene: Scene, plan, config: RasterConfig, grid, path: Path,
                     title: str = "") -> Path:
    """Planner paper Fig. 2-style row: BEV | risk map | goal map | SVF | plan vs demonstration."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ext = config.extent
    extent = (ext.left_m, -ext.right_m, -ext.back_m, ext.front_m)
    fig, axes = plt.subplots(1, 5, figsize=(17, 4.4), dpi=100)
    axes[0].imshow(raster_to_rgb(rasterize_scene(scene, config)), extent=extent, aspect="auto",
                   interpolation="nearest")
    axes[0].set_title("BEV raster")
    # Reads risk_map, goal_map, svf and waypoints only (never `policy`, which a space-time plan
    # leaves None); for a space-time plan risk_map is r_1 and svf the sum of its D_t.
    spacetime = has_spacetime(plan)
    panels = [(plan.risk_map, "risk map r_1 (reward now, <= 0)" if spacetime
               else "risk map (reward, <= 0)", "magma"),
              (plan.goal_map, "goal map", "viridis"),
              (np.log10(np.maximum(plan.svf, 1e-4)), "SVF (log10 expected visits)", "inferno")]
    for ax, (image, name, cmap) in zip(axes[1:4], panels):
        im = ax.imshow(image, extent=extent, aspect="auto", cmap=cmap, interpolation="nearest")
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
        ax.set_title(name)
    ax = axes[4]
    ax.imshow(raster_to_rgb(rasterize_scene(scene, config)), extent=extent, aspect="auto",
              interpolation="nearest", alpha=0.6)
    if scene.num_future_steps and scene.valid[scene.ego_index, scene.current_index + 1:].all():
        origin, heading = ego_pose(scene)
        demo = np.concatenate([[[0.0, 0.0]], ego_from_world(scene.ego_future_xy(), origin, heading)])
        ax.plot(demo[:, 1], demo[:, 0], "-o", color="#3ddc84", ms=3, lw=1.5, label="demonstration")
    mine = np.concatenate([[[0.0, 0.0]], plan.waypoints])
    ax.plot(mine[:, 1], mine[:, 0], "-o", color="#ff66ff", ms=3, lw=1.5, label="plan")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title("plan vs demonstration")
    for ax in axes:
        ax.set_xlim(ext.left_m, -ext.right_m)
        ax.set_ylim(-ext.back_m, ext.front_m)
        ax.set_xlabel("lateral y (m)")
    axes[0].set_ylabel("forward x (m)")
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def plan_figures(checkpoint: Path, data: Path, out: Path, count: int, seed: int = 0,
                 groups: tuple[str, ...] | None = None, goal: str = "route",
                 goal_variance: float | None = None) -> list[Path]:
    """Fig. 2-style panels of `count` windows spread over a dataset (or over its recorded
    `groups`), planned by a checkpoint towards the route rule's goal or the human's end."""
    from riskmap.data.dataset import DemoDataset, with_human_goal
    from riskmap.data.groups import windows_of_groups
    from riskmap.planner.riskmap_planner import load_planner

    planner = load_planner(checkpoint, seed=seed, goal_variance=goal_variance)
    dataset = DemoDataset(data, planner.grid.rows, raster=planner.raster)
    pool = windows_of_groups(dataset, groups) if groups else list(range(len(dataset)))
    picks = [pool[k] for k in np.unique(np.linspace(0, len(pool) - 1, min(count, len(pool))).astype(int))]
    paths = []
    for i in picks:
        scene = dataset.scene(int(i))
        plan = planner.plan(with_human_goal(scene) if goal == "human" else scene)
        origin, heading = ego_pose(scene)
        demo = ego_from_world(scene.ego_future_xy(), origin, heading)
        ade = float(np.linalg.norm(plan.waypoints - demo, axis=1).mean())
        where = dataset.group_of(int(i)) or dataset.source
        title = (f"{where} window {i}, {goal} goal: ego {scene.ego_state()[4]:.1f} m/s, "
                 f"ADE {ade:.1f} m, plan {1000 * plan.timings_s['total']:.0f} ms")
        paths.append(save_plan_panels(scene, plan, planner.raster, planner.grid,
                                      Path(out) / f"plan_{i:05d}.png", title))
        if has_spacetime(plan):
            paths.append(save_spacetime_strip(plan, planner.grid,
                                              Path(out) / f"plan_{i:05d}_steps.png", title,
                                              demo_xy=demo))
    return paths


def has_spacetime(plan) -> bool:
    """Whether a plan comes from a space-time planner (it carries r_t per step, `risk_steps`)."""
    return getattr(plan, "risk_steps", None) is not None


def save_spacetime_strip(plan, grid, path: Path, title: str = "",
                         demo_xy: np.ndarray | None = None, every: int | None = None) -> Path:
    """A space-time plan over time, in two rows of panels: on top the reward map r_t of each
    shown step (one colour scale for all), below the visitation D_t (probability that the ego is
    in each cell at step t, log10, one scale for all). Step t of T lies t * 6 / T s ahead; every
    panel marks the plan's waypoint at that time (index round(t_s / 0.5) - 1) and, if `demo_xy`
    ([12, 2] ego metres) is given, where the demonstration was then.

    `every`: show every `every`-th step, ending at the last; None shows at most about six
    (every second step of 12). Same imshow conventions as `save_plan_panels`' risk-map panel.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS

    risk = np.asarray(plan.risk_steps, dtype=np.float64)
    visits = plan.svf_steps
    steps = len(risk)
    if every is None:
        every = max(1, -(-steps // 6))
    if not (isinstance(every, (int, np.integer)) and every >= 1):
        raise ValueError(f"every={every!r}: must be an integer >= 1")
    shown = list(range(steps, 0, -every))[::-1]          # 1-based steps, ending at the last
    horizon_s = PLAN_STEPS * PLAN_DT_S

    ext = grid.extent
    extent = (ext.left_m, -ext.right_m, -ext.back_m, ext.front_m)
    chosen = risk[[t - 1 for t in shown]]
    r_low, r_high = float(chosen.min()), float(chosen.max())
    if r_high - r_low < 1e-9:
        r_low -= 1.0
    floor = 1e-4
    v_low, v_high = np.log10(floor), 0.0

    cols = len(shown)
    fig, axes = plt.subplots(2, cols + 1, figsize=(2.3 * cols + 1.2, 8.4), dpi=100, squeeze=False,
                             gridspec_kw={"width_ratios": [1.0] * cols + [0.07]})
    plan_path = np.concatenate([[[0.0, 0.0]], plan.waypoints])
    demo_path = None if demo_xy is None else np.concatenate([[[0.0, 0.0]], demo_xy])
    r_image = d_image = None
    for k, t in enumerate(shown):
        t_s = t * horizon_s / steps
        index = int(round(t_s / PLAN_DT_S)) - 1
        top, bottom = axes[0, k], axes[1, k]
        r_image = top.imshow(risk[t - 1], extent=extent, aspect="auto", cmap="magma",
                             interpolation="nearest", vmin=r_low, vmax=r_high)
        top.set_title(f"t = {t_s:.1f} s", fontsize=11)
        if visits is not None:
            d = np.log10(np.maximum(np.asarray(visits[t - 1], dtype=np.float64), floor))
            d_image = bottom.imshow(d, extent=extent, aspect="auto", cmap="inferno",
                                    interpolation="nearest", vmin=v_low, vmax=v_high)
        else:
            bottom.text(0.5, 0.5, "no visitation", transform=bottom.transAxes, ha="center")
        for ax in (top, bottom):
            if demo_path is not None:
                ax.plot(demo_path[:, 1], demo_path[:, 0], "-", color="#3ddc84", lw=0.9, alpha=0.6)
            ax.plot(plan_path[:, 1], plan_path[:, 0], "-", color="#ff66ff", lw=0.9, alpha=0.6)
            if demo_xy is not None and 0 <= index < len(demo_xy):
                ax.plot(demo_xy[index, 1], demo_xy[index, 0], "s", color="#3ddc84", ms=8,
                        mec="black", mew=1.0)
            if 0 <= index < len(plan.waypoints):
                ax.plot(plan.waypoints[index, 1], plan.waypoints[index, 0], "o", color="#ff66ff",
                        ms=8, mec="white", mew=1.2)
            ax.set_xlim(ext.left_m, -ext.right_m)
            ax.set_ylim(-ext.back_m, ext.front_m)
            ax.tick_params(labelsize=8)
            if k:
                ax.tick_params(labelleft=False)
        bottom.set_xlabel("lateral y (m)", fontsize=9)
    axes[0, 0].set_ylabel("reward r_t\nforward x (m)", fontsize=10)
    axes[1, 0].set_ylabel("visitation D_t\nforward x (m)", fontsize=10)
    fig.colorbar(r_image, cax=axes[0, -1]).set_label("reward r_t (<= 0)", fontsize=9)
    if d_image is not None:
        fig.colorbar(d_image, cax=axes[1, -1]).set_label("log10 P(ego in cell)", fontsize=9)
    else:
        axes[1, -1].axis("off")
    handles = [Line2D([], [], color="#ff66ff", marker="o", ms=7, mec="white", lw=0.9,
                      label="plan at t")]
    if demo_xy is not None:
        handles.append(Line2D([], [], color="#3ddc84", marker="s", ms=7, mec="black", lw=0.9,
                              label="demonstration at t"))
    axes[0, 0].legend(handles=handles, loc="lower left", fontsize=7.5, framealpha=0.85)
    fig.suptitle((title + "\n" if title else "")
                 + f"space-time plan: reward r_t and visitation D_t, {steps} steps over "
                 f"{horizon_s:g} s", fontsize=10)
    return _save(fig, path)


def plan_frame_writer(out_dir: Path, planner, stem: str, label: str, env_id: str,
                      name: str | None = None):
    """A rollout `on_plan` hook (riskmap.sim.loop.rollout.DriveHooks) that writes one PNG per replan,
    `out_dir/{stem}_tNNNN.png` (NNNN: the control step), titled `{label} t = …`. A planner
    without a raster of its own (constant velocity, a `py:` plug-in, IDM) is drawn on a raster
    of `env_id`'s family extent. A frame whose plan has no risk map says so in its title,
    naming the planner (`name`, default its class)."""
    from rasterize.config import FAMILY_EXTENTS, family_of_env
    from riskmap.sim.loop.plan import traits_of

    raster = traits_of(planner).raster
    if not isinstance(raster, RasterConfig):   # a plug-in may use the name for something else
        raster = RasterConfig(FAMILY_EXTENTS[family_of_env(env_id)])
    name = name or type(planner).__name__

    def write(run, scene, plan, step: int) -> None:
        title = f"{label} t = {run.time_s:.1f} s"
        note = missing_maps_note(plan, name)
        save_plan_png(scene, plan, raster, Path(out_dir) / f"{stem}_t{step:04d}.png",
                      f"{title}\n{note}" if note else title)
    return write


def missing_maps_note(plan, name: str) -> str:
    """What a frame of `plan` by planner `name` lacks, for its title: "" for a plan with a risk
    map, so that a risk-map planner's frames stay as they were."""
    if plan is None:
        return f"no plan, no risk map: {name} drives itself"
    if getattr(plan, "risk_map", None) is None:
        return f"no risk map: {name}"
    return ""
