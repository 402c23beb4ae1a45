"""PNG figures of a campaign report: metrics with confidence intervals, collision types, search."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from adversary.report.numbers import COLLISION_TYPES, planner_name


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _names(rows: list[dict]) -> dict[str, str]:
    """SPEC -> the display name its rows carry (figures label planners by name, never by SPEC)."""
    return {r["planner"]: planner_name(r) for r in rows}


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
    panels = [("collision_rate", "collision rate (%)", 100.0), ("safety_pct", "Safety % (danger, mean; lower is better)", 1.0),
              ("distance_m", "distance (m, mean)", 1.0), ("kinematic_mps", "kinematic value (m/s)", 1.0)]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.8), dpi=100)
    width = 0.8 / max(1, len(planners))
    colours = plt.get_cmap("tab10")
    by_key = {(r["planner"], r["attack"]): r for r in rows}
    name = _names(rows)
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
            ax.bar(xs, ys, width, yerr=[lo, hi], capsize=3, color=colours(j), label=name[planner])
        ax.set_xticks(range(len(attacks)), attacks, rotation=15, fontsize=8)
        ax.set_title(title, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle("planners side by side (bars: 95% Wilson / bootstrap intervals)", fontsize=10)
    return _save(fig, path)


def headline_figure(rows: list[dict], attack_order: list[str], path: Path) -> str:
    """The report's first figure: the rate of failures that count (valid, avoidable, at fault)
    per planner and attack, one panel per scenario family (numbers.py's by-family rows), solid
    bars with their 95% Wilson intervals and k/n above; every collision's rate as an outline
    around each bar."""
    from matplotlib.patches import Patch

    plt = _plt()
    rows = [r for r in rows if r["collision_rate"] is not None and r.get("failure_rate") is not None]
    families = sorted({r["family"] for r in rows})
    planners = sorted({r["planner"] for r in rows})
    colour = {p: plt.get_cmap("tab10")(j % 10) for j, p in enumerate(planners)}
    by_key = {(r["family"], r["planner"], r["attack"]): r["failure_rate"] for r in rows}
    every = {(r["family"], r["planner"], r["attack"]): r["collision_rate"] for r in rows}
    order = [a for a in attack_order if any(r["attack"] == a for r in rows)]
    order += sorted({r["attack"] for r in rows} - set(order))
    attacks_of = {f: [a for a in order if any((f, p, a) in by_key for p in planners)] for f in families}
    planners_of = {f: [p for p in planners if any((f, p, a) in by_key for a in order)] for f in families}
    slots = [len(attacks_of[f]) * (len(planners_of[f]) + 0.8) for f in families]
    width_in = min(12.4, max(7.5, 3.5 + 0.5 * sum(slots)))
    # Attack names turned when the longest is wider than its group in the narrowest panel.
    group_in = min(0.8 * width_in * slot / sum(slots) / len(attacks_of[f]) for f, slot in zip(families, slots))
    turn = 0.07 * max(len(a) for a in order) > 0.95 * group_in      # about 0.07 in a character
    fig, axes = plt.subplots(1, len(families), figsize=(width_in, 3.8), dpi=100, squeeze=False,
                             gridspec_kw={"width_ratios": slots})
    for ax, family in zip(axes[0], families):
        here = planners_of[family]
        width = 0.8 / len(here)
        for i, attack in enumerate(attacks_of[family]):
            for j, planner in enumerate(here):
                stat = by_key.get((family, planner, attack))
                if stat is None:
                    continue
                x = i + (j - (len(here) - 1) / 2) * width
                v, lo, hi = 100 * stat["value"], 100 * stat["lo"], 100 * stat["hi"]
                raw = every[family, planner, attack]
                ax.bar(x, 100 * raw["value"], width * 0.9, fill=False, edgecolor=colour[planner], linewidth=1.2,
                       linestyle="--")
                ax.bar(x, v, width * 0.9, color=colour[planner], edgecolor=colour[planner], linewidth=1.5)
                ax.errorbar(x, v, yerr=[[v - lo], [hi - v]], fmt="none", ecolor="#333", capsize=3, lw=1)
                ax.text(x, max(hi, 100 * raw["value"]) + 1.5, f"{stat['k']}/{stat['n']}", ha="center",
                        va="bottom", fontsize=7)
        labels = attacks_of[family]
        ax.set_xticks(range(len(labels)), labels, fontsize=8, rotation=15 if turn else 0,
                      ha="right" if turn else "center")
        ax.set_xlim(-0.6, len(labels) - 0.4)
        ax.set_ylim(0, 112)
        ax.set_yticks([0, 25, 50, 75, 100])
        jobs = sum(by_key[family, p, a]["n"] for p in here for a in labels if (family, p, a) in by_key)
        ax.set_title(f"{family} ({jobs} jobs)", fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("failures that count (%)")
    name = _names(rows)
    names = [name[p] for p in planners]
    legend_in = 0.7 + 0.058 * max(len(name) for name in names + ["every collision"])     # about 0.058 in a character
    fig.legend([Patch(color=colour[p]) for p in planners] + [Patch(fill=False, edgecolor="#555", linestyle="--")],
               names + ["every collision"], loc="center right", fontsize=8, frameon=False, title="planner",
               title_fontsize=8)
    fig.suptitle("valid, avoidable, at-fault failures per planner and attack\n"
                 "(solid, 95% Wilson intervals, k/n jobs above; dashed outline: every collision)", fontsize=10)
    return _save(fig, path, rect=(0, 0, 1 - legend_in / width_in, 0.97))


def collision_types_figure(rows: list[dict], path: Path) -> str:
    plt = _plt()
    labels = [f"{planner_name(r)}\n{r['attack']}" for r in rows]
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
    name = _names(history)
    # Distinct line styles and markers: identical searches (e.g. a guard that never intervenes)
    # would otherwise hide each other.
    styles, markers = ("-", "--", ":", "-."), "osD^v<>"
    for i, ((planner, attack), runs) in enumerate(groups.items()):
        depth = max(len(h["generations"]) for h in runs)
        size = sum(g.get("evaluations", 0) for g in runs[0]["generations"][:1]) * len(runs)
        label = (f"{name[planner]} / {attack} ({len(runs)} search{'es' if len(runs) > 1 else ''}"
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
