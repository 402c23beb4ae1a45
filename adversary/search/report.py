"""Summary and figures of one search run (OUT of `adversary search`).

    summary.json                     collision share, the failures that count among them
                                     (riskmap.sim.records.failures), per-generation counts, failure
                                     diversity, the least-altered failure
    collisions_per_generation.png    collisions per generation (the search paper's Fig. 10)
    best_failure_evolution.png       per generation, the least-altered failing vector (Figs. 11-12)
    pareto_front.png                 objectives of every feasible evaluation, first front marked
    best_failure/frame_*.png         the least-altered failure replayed, BEV frames (Fig. 13)

Failure diversity (the paper's Table 1): failing vectors are normalised to [0, 1] by their
bounds; for each failure the average Euclidean distance to every other failure is taken, and
the diversity is the range [min, max] of these averages.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from adversary.search.scenarios import Template, get_template
from riskmap.infra.atomic import write_json
from riskmap.registry import display_name
from riskmap.sim.records.failures import summarise_failures


def load_run(out: Path) -> tuple[dict, list[list[dict]]]:
    """(run.json config, evaluation records grouped by generation, in evaluation order)."""
    out = Path(out)
    config = json.loads((out / "run.json").read_text())["config"]
    generations = []
    for path in sorted((out / "generations").glob("gen_*.json")):
        keys = json.loads(path.read_text())["keys"]
        generations.append([json.loads((out / "evaluations" / f"{k}.json").read_text())
                            for k in keys])
    return config, generations


def failure_diversity(template: Template, failing_x: np.ndarray) -> tuple[float, float] | None:
    """(min, max) over failures of the mean Euclidean distance to the other failures, in the
    normalised parameter space; None with fewer than two failures. failing_x [n, n_params]."""
    if len(failing_x) < 2:
        return None
    z = template.normalised(failing_x)
    d = np.linalg.norm(z[:, None, :] - z[None, :, :], axis=2)
    mean = d.sum(axis=1) / (len(z) - 1)
    return float(mean.min()), float(mean.max())


def describe(template: Template, params: dict[str, float], limit: int = 4) -> str:
    """The parameters that differ most from the base scene, in words."""
    deviations = sorted(((abs(params[p.name] - p.neutral) / (p.high - p.low), p)
                         for p in template.parameters), key=lambda t: -t[0])
    parts = [f"{p.name} {params[p.name]:.2f} {p.unit} (base {p.neutral:g})"
             for dev, p in deviations[:limit] if dev > 1e-3]
    return f"{template.name}: " + ("; ".join(parts) if parts else "the base scene")


def _least_altered(records: list[dict]) -> dict | None:
    failing = [r for r in records if r["collided"]]
    return min(failing, key=lambda r: r["alteration"]) if failing else None


def _plot_collisions(counts: list[int], sizes: list[int], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.4), dpi=110)
    gens = np.arange(1, len(counts) + 1)
    ax.bar(gens, sizes, color="#dddddd", label="evaluations")
    ax.bar(gens, counts, color="#d9480f", label="collisions")
    ax.set_xlabel("generation")
    ax.set_ylabel("count")
    ax.set_xticks(gens)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _plot_evolution(template: Template, best: list[dict | None], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.0), dpi=110)
    gens = np.arange(1, len(best) + 1)
    z = np.array([template.normalised(r["x"]) if r else np.full(len(template.parameters), np.nan)
                  for r in best])
    neutral = template.normalised(template.neutral)
    for i, p in enumerate(template.parameters):
        (line,) = ax.plot(gens, z[:, i], "-o", ms=3.5, lw=1.2, label=p.name)
        # The base scene's value, in the same colour, left of generation 1.
        ax.plot([0.5], [neutral[i]], marker="_", ms=16, mew=2.5, color=line.get_color())
    ax.set_xlim(0.3, len(best) + 0.5)
    ax.set_xlabel("generation (dashes at left: base scene; no marker: no failure that generation)")
    ax.set_ylabel("parameter, normalised to its bounds")
    ax.set_ylim(-0.05, 1.05)
    ax.set_xticks(gens)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=6.5, loc="center left", bbox_to_anchor=(1.0, 0.5))
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _plot_pareto(records: list[dict], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

    feasible = [r for r in records if r["feasible"]]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), dpi=110)
    if feasible:
        front = set(NonDominatedSorting().do(np.array([r["F"] for r in feasible]),
                                             only_non_dominated_front=True).tolist())
        for ax, key, label in ((axes[0], "journey_m", "journey distance (m), maximised"),
                               (axes[1], "total_distance_m", "Σ_t distance to target (m), minimised")):
            for collided, colour, name in ((False, "#4dabf7", "no collision"),
                                           (True, "#d9480f", "collision")):
                pts = [(r["alteration"], r[key]) for r in feasible if r["collided"] == collided]
                if pts:
                    ax.scatter(*np.array(pts).T, s=14, color=colour, alpha=0.7, label=name)
            pts = np.array([(feasible[i]["alteration"], feasible[i][key]) for i in sorted(front)])
            ax.scatter(*pts.T, s=60, facecolors="none", edgecolors="black", label="first front")
            ax.set_xlabel("scene alteration (minimised)")
            ax.set_ylabel(label)
            ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def render_failure_frames(template: Template, record: dict, config: dict, out_dir: Path,
                          every_s: float = 1.0) -> list[Path]:
    """Replay one evaluation and save BEV frames every `every_s` seconds and at its last step."""
    from adversary.search.evaluation import EvaluationConfig, run_scenario
    from adversary.search.scenarios import ENV_ID
    from rasterize.config import Extent, RasterConfig
    from riskmap.figures.panels import save_scene_png

    evaluation = EvaluationConfig(config["planner"], config["template"], config["seed"],
                                  config["episode_s"])
    runs = []
    drive, _ = run_scenario(template, np.asarray(record["x"]), evaluation,
                            on_step=lambda run: runs.append(run) if not runs else None)
    recorder = runs[0].recorder
    # Close-up around the ego (the planner's 200 m highway extent makes both cars specks).
    raster = RasterConfig(Extent(front_m=45.0, back_m=25.0, left_m=9.0, right_m=9.0), 280, 144)
    last = recorder.num_steps - 1
    stride = round(every_s * evaluation.control_hz)
    steps = sorted(set(range(0, last + 1, stride)) | {last})
    outcome = "collision" if drive["collided"] else "no collision"
    paths = []
    for step in steps:
        remaining_s = (last - step) / evaluation.control_hz
        future_s = min(3.0, np.floor(remaining_s / 0.5) * 0.5)
        scene = recorder.scene(step, 2.0, future_s, source=ENV_ID)
        title = (f"{display_name(config['planner'])} on {template.name}, t = {step / evaluation.control_hz:.1f} s "
                 f"({outcome} at {drive['simulated_s']:.1f} s)")
        paths.append(save_scene_png(scene, raster, out_dir / f"frame_{step:04d}.png", title))
    return paths


def write_report(out: Path, frames: bool = True) -> dict:
    out = Path(out)
    config, generations = load_run(out)
    template = get_template(config["template"])
    records = [r for gen in generations for r in gen]
    counts = [sum(r["collided"] for r in gen) for gen in generations]
    sizes = [len(gen) for gen in generations]
    failing = np.array([r["x"] for r in records if r["collided"]]).reshape(-1, len(template.parameters))
    unique_failing = np.unique(failing, axis=0)
    diversity = failure_diversity(template, unique_failing)
    best = _least_altered(records)
    per_generation_best = [_least_altered(gen) for gen in generations]
    label = f"{config['algorithm']} | {config['planner']} | {config['template']}"
    _plot_collisions(counts, sizes, f"collisions per generation: {label}",
                     out / "collisions_per_generation.png")
    _plot_evolution(template, per_generation_best,
                    f"least-altered failure of each generation: {label}",
                    out / "best_failure_evolution.png")
    _plot_pareto(records, label, out / "pareto_front.png")
    summary = {
        "config": config,
        "evaluations": len(records),
        "feasible": sum(r["feasible"] for r in records),
        "collisions": int(sum(counts)),
        "collision_share": sum(counts) / len(records) if records else None,
        # the collisions that count (valid, avoidable, at fault) and each class, over every
        # evaluation; evaluations stored before the classification count as unknown
        "failures": summarise_failures([r.get("failure") for r in records if r["collided"]], len(records)),
        "collisions_per_generation": counts,
        "evaluations_per_generation": sizes,
        "distinct_failures": len(unique_failing),
        "failure_diversity": diversity,
        "least_altered_failure": None if best is None else {
            "params": best["params"], "alteration": best["alteration"],
            "simulated_s": best["simulated_s"], "description": describe(template, best["params"]),
        },
        "least_altered_failure_per_generation": [
            None if r is None else {"alteration": r["alteration"], "params": r["params"]}
            for r in per_generation_best],
    }
    if frames and best is not None:
        render_failure_frames(template, best, config, out / "best_failure")
    write_json(out / "summary.json", summary)
    return summary
