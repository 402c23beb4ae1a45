"""A bird's-eye PNG of one judged attack (world frame, equal aspect, cropped to the agents).

Lanes from the window; every window row's 2 s past in grey; the generated (spliced) futures of
the other rows in blue and the adversary's in red; the ego's closed-loop path in green (dashed:
the human's logged future for comparison). Boxes are drawn at the collision time (the final
time without one), with the collision point marked, and the key metrics in the title. A
collision the ego could have avoided (`riskmap.sim.records.failures`) shows the alternative that avoids
it, dotted, from where the ego reacted (a diamond) to the collision time, with its box there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from adversary.crash.judge import Rollout, splice_tracks
from adversary.crash.scenes import SceneRecord
from rasterize.frames import box_corners
from riskmap.infra.atomic import atomic_write
from riskmap.sim.records.failures import failure_words
from riskmap.sim.records.record import current_names

_GREY, _BLUE, _RED, _GREEN = "0.55", "tab:blue", "tab:red", "tab:green"


def _title_line(metrics: dict) -> str:
    metrics = current_names(metrics)      # metrics of results stored under the judge's old names
    if metrics["collision"]:
        what = (f"collision {metrics['collision_type']} at {metrics['collision_time_s']:.1f} s, "
                f"IoU {metrics['collision_iou']:.2f}, |dv| {metrics['kinematic_value_mps']:.1f} m/s, "
                f"solution {'yes' if metrics['solution_found'] else 'no'}")
        if metrics.get("failure"):
            what += "; " + failure_words(metrics["failure"])
    else:
        gap = metrics["min_gap_m"]
        what = "no collision" + (f", min gap {gap:.1f} m" if gap is not None else "")
    off = [name for name, key in (("adversary", "adversary_off_road"), ("other", "other_off_road"),
                                  ("ego", "off_road")) if metrics[key]]
    return (f"{metrics['planner']}: {what}; ego min accel {metrics['ego_min_accel_mps2']:.1f} m/s²"
            + (f"; off road: {', '.join(off)}" if off else ""))


def save_attack_panel(record: SceneRecord, tracks: np.ndarray, rows, adversary_row: int,
                      rollout: Rollout, metrics: dict, path: Path, title: str) -> None:
    """Write the panel of one attack to `path` (PNG); see the module docstring."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon as PatchPolygon

    spliced = splice_tracks(record, tracks, rows)
    window, k0, stride = record.window, record.t0_step, record.stride
    end = k0 + stride * record.scene.future_steps
    row_ids = rollout.row_ids(record)
    ego_rec = rollout.ego
    coll_step = (round(metrics["collision_time_s"] / rollout.dt_s) if metrics["collision"]
                 else int(np.flatnonzero(rollout.valid[ego_rec])[-1]))

    # Crop: the ego's path and the adversary's with a margin, widened to a readable height; the
    # figure takes the crop's shape so that equal aspect leaves no empty bands.
    adv_agent = int(record.agent_ids[adversary_row])
    focus = np.concatenate([window.states[0, :window.current_index + 1, :2],
                            rollout.states[ego_rec][rollout.valid[ego_rec], :2],
                            spliced.states[adv_agent, :end + 1][spliced.valid[adv_agent, :end + 1], :2]])
    lo, hi = focus.min(axis=0) - 12.0, focus.max(axis=0) + 12.0
    centre, span = 0.5 * (lo + hi), np.maximum(hi - lo, [60.0, 24.0])
    span[1] = max(span[1], span[0] / 5.0)
    lo, hi = centre - 0.5 * span, centre + 0.5 * span
    width_in = 11.0
    fig, ax = plt.subplots(figsize=(width_in, min(9.0, 0.8 * width_in * span[1] / span[0]) + 1.4), dpi=110)
    for lane in window.lanes:
        ax.add_patch(PatchPolygon(lane.polygon(), closed=True, facecolor="0.93", edgecolor="0.75",
                                  linewidth=0.6, zorder=0))
    for row, agent in enumerate(record.agent_ids):
        past = window.states[row, :window.current_index + 1][window.valid[row, :window.current_index + 1]]
        ax.plot(past[:, 0], past[:, 1], color=_GREY, linewidth=2, zorder=2)
        if row == 0:
            continue
        future = spliced.states[agent, k0:end + 1][spliced.valid[agent, k0:end + 1]]
        colour = _RED if row == adversary_row else _BLUE
        ax.plot(future[:, 0], future[:, 1], color=colour, linewidth=2.5 if row == adversary_row else 1.2,
                zorder=6 if row == adversary_row else 2)
        knots = spliced.states[agent, k0 + stride:end + 1:stride]
        ax.plot(knots[:, 0], knots[:, 1], "o", color=colour, markersize=2.5, zorder=3)
        rec = int(row_ids[row])
        if rec >= 0 and rollout.valid[rec, min(coll_step, rollout.valid.shape[1] - 1)]:
            state = rollout.states[rec, coll_step]
            ax.add_patch(PatchPolygon(box_corners(state[:2], state[2:4], *rollout.sizes[rec]), closed=True,
                                      facecolor=colour, alpha=0.35, edgecolor=colour, zorder=4))
    human = spliced.states[spliced.ego_id, k0:end + 1, :2]
    ax.plot(human[:, 0], human[:, 1], color=_GREEN, linewidth=1, linestyle="--", zorder=3,
            label="ego: human log")
    driven = rollout.states[ego_rec][rollout.valid[ego_rec]]
    ax.plot(driven[:, 0], driven[:, 1], color=_GREEN, linewidth=2.2, zorder=5, label="ego: planner")
    ego_state = rollout.states[ego_rec, coll_step]
    ax.add_patch(PatchPolygon(box_corners(ego_state[:2], ego_state[2:4], *rollout.sizes[ego_rec]),
                              closed=True, facecolor=_GREEN, alpha=0.45, edgecolor=_GREEN, zorder=6))
    failure = metrics.get("failure") or {}
    if metrics["collision"] and failure.get("avoidance"):
        from riskmap.sim.records.alternatives import alternative_track

        react = round(failure["reaction_time_s"] / rollout.dt_s)
        avoid = failure["avoidance"]
        alt = alternative_track(rollout.states, rollout.valid, ego_rec, react, coll_step - react, rollout.dt_s,
                                avoid["accel_mps2"], avoid["offset_m"], path_until=rollout.states.shape[1] - 1)
        ax.plot(alt[:, 0], alt[:, 1], color="black", linewidth=1.6, linestyle=":", zorder=7,
                label=f"avoids it: {avoid['accel_mps2']:+.0f} m/s²" + (f", {avoid['offset_m']:+.1f} m across"
                                                                      if avoid["offset_m"] else ""))
        ax.plot(*rollout.states[ego_rec, react, :2], marker="D", color="black", markersize=5, zorder=7)
        ax.add_patch(PatchPolygon(box_corners(alt[-1, :2], alt[-1, 2:4], *rollout.sizes[ego_rec]), closed=True,
                                  fill=False, edgecolor="black", linestyle=":", zorder=7))
    if metrics["collision"]:
        adv_state = rollout.states[int(row_ids[adversary_row]), coll_step]
        point = 0.5 * (ego_state[:2] + adv_state[:2])
        ax.plot(*point, marker="*", color="black", markersize=14, zorder=7, label="collision")
    ax.plot([], [], color=_GREY, linewidth=2, label="past 2 s")
    ax.plot([], [], color=_BLUE, label="others' futures")
    ax.plot([], [], color=_RED, linewidth=2, label="adversary")

    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7)
    when = f"boxes at {coll_step * rollout.dt_s:.1f} s"
    ax.set_title(f"{title} ({when})\n{_title_line(metrics)}", fontsize=9)
    fig.tight_layout()
    atomic_write(Path(path), lambda f: fig.savefig(f, format="png", bbox_inches="tight"))
    plt.close(fig)


def example_panels(out_dir: Path) -> list[dict]:
    """Two hand-made attacks on highway-v0 (seed 0), judged and drawn into `out_dir`: the car
    ahead in the ego's lane brakes hard in front of the human's log played back (episode 9), and
    a car two lanes over cuts into the ego's lane and brakes in front of the risk-map planner
    (episode 0)."""
    from adversary.crash.judge import braking_track, judge, rollout
    from adversary.crash.scenes import AttackScene, record_attack_scene
    from riskmap.registry import cached_planner

    cases = [("brake_ahead_replay", AttackScene("highway-v0", 0, 9), 3, False, "replay"),
             ("cut_in_riskmap", AttackScene("highway-v0", 0, 0), 1, True,
              "riskmap:checkpoints/riskmap_highway")]
    results = []
    for name, scene, row, cut_in, spec in cases:
        record = record_attack_scene(scene)
        tracks = braking_track(record, row, into_ego_lane=cut_in)[None]
        planner = cached_planner(spec)
        result = rollout(record, tracks, [row], planner, spec)
        metrics = judge(record, tracks, [row], row, planner, spec, result=result)
        title = f"{scene.env_id} seed {scene.scene_seed} episode {scene.episode}, t0 {scene.t0_s:g} s: {name}"
        save_attack_panel(record, tracks, [row], row, result, metrics, Path(out_dir) / f"{name}.png", title)
        results.append({"name": name, **metrics})
    return results
