"""PNG figures of a campaign report: metrics with confidence intervals, collision types, search."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from adversary.report.numbers import COLLISION_TYPES


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def short_spec(spec: str) -> str:
    """A planner SPEC short enough for a figure label: `riskmap:a/b/ckpt` -> `riskmap:ckpt`."""
    kind, sep, arg = spec.partition(":")
    return f"{kind}:{Path(arg).name}" if sep and "/" in arg else spec


def _save(fig, path: Path, rect=(0, 0, 1, 1)) -> str:
    """rect: the part of the figure (left, bottom, right, top in 0..1) the axes are laid out in."""
    fig.tight_layout(rect=rect)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    _plt().close(fig)
    return path.name


def metrics_figure(rows: list[dict], path: Path) -> str:
    """Grouped bars per attack, one bar per planner, with 95% intervals."""
    plt = _plt()
    attacks = sorted({r["attack"] for r in rows})
    planners = sorted({r["planner"] for r in rows})
    panels = [("collision_rate", "collision rate (%)", 100.0), ("safety_pct", "Safety % (mean)", 1.0),
              ("distance_m", "distance (m, mean)", 1.0), ("kinematic_mps", "kinematic value (m/s)", 1.0)]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.8), dpi=100)
    width = 0.8 / max(1, len(planners))
    colours = plt.get_cmap("tab10")
    by_key = {(r["planner"], r["attack"]): r for r in rows}
    for ax, (key, title, scale) in zip(axes, panels):
        for j, planner in enumerate(planners):
            xs, ys, lo, hi = [], [], [], []
            for i, attack in enumerate(attacks):
                stat = by_key.get((planner, attack), {}).get(key)
                if stat is None:
                    continue
                xs.append(i + (j - (len(planners) - 1) / 2) * width)
                ys.append(stat["value"] * scale)
                lo.append((stat["value"] - stat["lo"]) * scale)
                hi.append((stat["hi"] - stat["value"]) * scale)
            ax.bar(xs, ys, width, yerr=[lo, hi], capsize=3, color=colours(j), label=short_spec(planner))
        ax.set_xticks(range(len(attacks)), attacks, rotation=15, fontsize=8)
        ax.set_title(title, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle("planners side by side (bars: 95% Wilson / bootstrap intervals)", fontsize=10)
    return _save(fig, path)


def collision_types_figure(rows: list[dict], path: Path) -> str:
    plt = _plt()
    labels = [f"{short_spec(r['planner'])}\n{r['attack']}" for r in rows]
    fig, ax = plt.subplots(figsize=(max(5.0, 1.3 * len(rows) + 2), 3.6), dpi=100)
    bottom = np.zeros(len(rows))
    colours = plt.get_cmap("Set2")
    for k, kind in enumerate(COLLISION_TYPES):
        counts = np.array([r[kind] for r in rows], dtype=float)
        ax.bar(range(len(rows)), counts, 0.6, bottom=bottom, label=kind, color=colours(k))
        bottom += counts
    ax.set_xticks(range(len(rows)), labels, fontsize=7, rotation=20, ha="right")
    ax.set_ylabel("collisions")
    from matplotlib.ticker import MaxNLocator

    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title("collision types (relative heading and position of the partner)", fontsize=10)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, path)


def search_figure(history: list[dict], path: Path) -> str:
    """Collisions per generation (left) and the Pareto front's first two objectives (right), one
    colour per (planner, attack): the searches of its jobs summed per generation, fronts pooled."""
    from matplotlib.ticker import MaxNLocator

    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6), dpi=100)
    groups: dict[tuple[str, str], list[dict]] = {}
    for h in history:
        groups.setdefault((h["planner"], h["attack"]), []).append(h)
    # Distinct line styles and markers: identical searches (e.g. a guard that never intervenes)
    # would otherwise hide each other.
    styles, markers = ("-", "--", ":", "-."), "osD^v<>"
    for i, ((planner, attack), runs) in enumerate(groups.items()):
        depth = max(len(h["generations"]) for h in runs)
        size = sum(g.get("evaluations", 0) for g in runs[0]["generations"][:1]) * len(runs)
        label = (f"{short_spec(planner)} / {attack} ({len(runs)} search{'es' if len(runs) > 1 else ''}"
                 f"{f', {size} evaluations a generation' if size else ''})")
        if depth:
            collisions = np.zeros(depth)
            for h in runs:
                collisions[:len(h["generations"])] += [g.get("collisions", 0) for g in h["generations"]]
            axes[0].plot(np.arange(1, depth + 1), collisions, styles[i % 4], marker=markers[i % 7],
                         ms=4, label=label)
        fronts = [np.asarray(h["pareto_front"], dtype=float) for h in runs]
        fronts = [f for f in fronts if f.ndim == 2 and f.shape[1] >= 2]
        if fronts:
            front = np.concatenate(fronts)
            axes[1].scatter(front[:, 0], front[:, 1], s=18, marker=markers[i % 7], alpha=0.6, label=label)
            names = runs[0]["objective_names"] or ["objective 1", "objective 2"]
            axes[1].set_xlabel(names[0])
            axes[1].set_ylabel(names[1] if len(names) > 1 else "objective 2")
    axes[0].xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[0].yaxis.set_major_locator(MaxNLocator(integer=True))
    axes[0].set_xlabel("generation")
    axes[0].set_ylabel("collisions (summed over searches)")
    axes[0].set_title("collisions per generation", fontsize=10)
    axes[1].set_title("Pareto fronts (first two objectives)", fontsize=10)
    for ax in axes:
        ax.grid(alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    if not handles:
        handles, labels = axes[1].get_legend_handles_labels()
    if handles:                        # one legend for both panels, below them
        fig.legend(handles, labels, fontsize=7.5, loc="lower center", ncol=1 if len(labels) > 2 else 2,
                   bbox_to_anchor=(0.5, 0.0))
    return _save(fig, path, rect=(0, 0.045 * len(labels) + 0.03, 1, 1))
