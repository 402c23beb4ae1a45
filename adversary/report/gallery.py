"""The panel of a worst scene: BEV | risk map | SVF | trajectories (matplotlib).

Drawn from the npz artifact each job leaves (adversary.report.frames.load_artifact): the scene of
the last plan and the plan's maps, and the final scene with its history. A crash attack's
artifact holds its own panel (adversary.crash.panel), which is used as it is. The frame strip,
the risk map over time and the animation of every job are adversary.report.frames'.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from adversary.attacks.recorded import job_raster
from adversary.report.frames import load_artifact, scene_at
from rasterize.raster import rasterize_scene
from riskmap.figures.panels import raster_to_rgb


def _bev(ax, scene, raster, title: str) -> None:
    ext = raster.extent
    ax.imshow(raster_to_rgb(rasterize_scene(scene, raster)), interpolation="nearest", aspect="auto",
              extent=(ext.left_m, -ext.right_m, -ext.back_m, ext.front_m))
    stretch = (ext.length_m / raster.rows) / (ext.width_m / raster.cols)
    # Highway rasters squeeze 240 m x 40 m into a square: small heading changes look steep.
    note = f"\n[lateral axis stretched x{stretch:.0f}]" if stretch > 1.5 else ""
    ax.set_title(title + note, fontsize=9)
    ax.set_xlabel("lateral y (m)", fontsize=8)


def _map(ax, fig, image, title: str, cmap: str) -> None:
    if image is None:
        ax.text(0.5, 0.5, "no map:\nthis planner makes none", ha="center", va="center", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    else:
        im = ax.imshow(image, cmap=cmap, interpolation="nearest", aspect="auto")
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
        ax.set_xlabel("grid column (row 0 = front)", fontsize=8)
    ax.set_title(title, fontsize=9)


def _trajectories(ax, scene, adversary: int) -> None:
    """World-frame paths over the final scene's window; boxes at the last step."""
    from matplotlib.patches import Polygon

    from rasterize.frames import box_corners

    now = scene.current_index
    ego_xy = scene.states[scene.ego_index, now, :2]
    for a in range(scene.num_agents):
        xy = scene.states[a, :now + 1, :2][scene.valid[a, :now + 1]]
        if len(xy) == 0 or np.linalg.norm(xy[-1] - ego_xy) > 60:
            continue
        colour = "#e03131" if a == scene.ego_index else "#f59f00" if a == adversary else "#868e96"
        ax.plot(xy[:, 0], xy[:, 1], "-", color=colour, lw=2.0 if colour != "#868e96" else 1.0)
        if scene.valid[a, now]:
            s = scene.states[a, now]
            ax.add_patch(Polygon(box_corners(s[:2], s[2:4], *scene.sizes[a]), closed=True,
                                 color=colour, alpha=0.8))
    for lane in scene.lanes:
        for side in (lane.left, lane.right):
            ax.plot(side[:, 0], side[:, 1], "-", color="#ced4da", lw=0.6, zorder=0)
    ax.set_xlim(ego_xy[0] - 45, ego_xy[0] + 45)
    ax.set_ylim(ego_xy[1] - 30, ego_xy[1] + 30)
    ax.set_aspect("equal")
    ax.set_title("trajectories (ego red, adversary orange), last 8 s", fontsize=9)
    ax.set_xlabel("world x (m)", fontsize=8)


def gallery_panel(artifact: Path, env_id: str, out_dir: Path, stem: str, title: str) -> str | None:
    """The panel PNG's name, written into out_dir for one job's artifact; None when the artifact
    holds neither a scene nor an attack's own panel."""
    data = load_artifact(artifact)
    panel = out_dir / f"{stem}_panels.png"
    if data.crash_panel_png is not None:
        panel.write_bytes(data.crash_panel_png)
        return panel.name
    if data.final is None:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    raster = job_raster(env_id, 160, 160)
    final = data.final
    fig, axes = plt.subplots(1, 4, figsize=(17, 4.3), dpi=90)
    plan = data.plan
    scene = (data.plan_scene if data.plan_scene is not None
             else scene_at(final, final.current_index, raster.history_s))
    when = "at the last plan" if data.plan_scene is not None else "at the end (no plans: the ego drove itself)"
    _bev(axes[0], scene, raster, f"BEV {when}, t = {scene.time_s:.1f} s")
    if "waypoints" in plan:
        wp = np.concatenate([[[0.0, 0.0]], plan["waypoints"]])
        axes[0].plot(wp[:, 1], wp[:, 0], "-o", color="#ff66ff", ms=2.5, lw=1.3, label="plan 6 s")
        axes[0].legend(fontsize=7, loc="upper right")
    _map(axes[1], fig, plan.get("risk_map"), "risk map (reward <= 0)", "magma")
    svf = plan.get("svf")
    _map(axes[2], fig, None if svf is None else np.log10(np.maximum(svf, 1e-4)),
         "SVF (log10 expected visits)", "inferno")
    _trajectories(axes[3], final, data.adversary_index)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(panel)
    plt.close(fig)
    return panel.name
