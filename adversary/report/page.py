"""`adversary report DIR`: report.html (Jinja2) + PNG figures + report.json from a campaign.

report.json holds every number on the page: "results" (a function of the records alone, so a
resumed or distributed campaign gives the same), "timing" (machine-dependent), the config,
versions and provenance.
"""

from __future__ import annotations

import json
import platform
from importlib import metadata
from pathlib import Path

from adversary.attacks.registry import attack_entry
from adversary.campaign.store import ResultStore
from adversary.report.figures import collision_types_figure, metrics_figure, search_figure, short_spec
from adversary.report.numbers import COLLISION_TYPES, report_numbers
from rasterize.errors import InputError
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.provenance import provenance

_PACKAGES = ("riskmap-toolkit", "numpy", "torch", "highway-env", "gymnasium", "scipy", "matplotlib",
             "jinja2", "pyyaml", "ray")


def versions() -> dict:
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def _fmt_rate(stat) -> str:
    if stat is None:
        return "–"
    return f"{100 * stat['value']:.0f}% [{100 * stat['lo']:.0f}, {100 * stat['hi']:.0f}] ({stat['k']}/{stat['n']})"


def _fmt_mean(stat, digits: int = 1) -> str:
    if stat is None:
        return "–"
    return f"{stat['value']:.{digits}f} [{stat['lo']:.{digits}f}, {stat['hi']:.{digits}f}] (n={stat['n']})"


def _environment():
    from jinja2 import Environment, PackageLoader, select_autoescape

    env = Environment(loader=PackageLoader("adversary.report", "templates"),
                      autoescape=select_autoescape(["html", "j2"]), trim_blocks=True,
                      lstrip_blocks=True)
    env.filters["rate"] = _fmt_rate
    env.filters["mean"] = _fmt_mean
    return env


def _outcome(worst: dict) -> str:
    """A worst scene's outcome in a few words (a crash attack measures no Safety %, and its
    collisions with other vehicles than the adversary have no type or kinematic value)."""
    if worst["collided"]:
        if worst["kinematic_mps"] is None:
            return "collision (not with the adversary)"
        return f"collision ({worst['collision_type']}, {worst['kinematic_mps']:.1f} m/s)"
    if worst["safety_pct"] is None:
        return "no collision"
    return f"no collision, Safety {worst['safety_pct']:.0f}%"


def make_report(campaign_dir: Path, out_dir: Path | None = None) -> dict:
    """Write report.html, report.json and the PNGs into out_dir (default: the campaign dir)."""
    campaign_dir = Path(campaign_dir)
    meta_path = campaign_dir / "campaign.json"
    if not meta_path.is_file():
        raise InputError(f"{campaign_dir}: no campaign.json; pass a directory written by "
                         "`adversary stress-test --out`")
    out_dir = Path(out_dir or campaign_dir)
    figures = out_dir / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    meta = json.loads(meta_path.read_text())
    store = ResultStore(campaign_dir)
    records = [r for r in store.records() if r["job_id"] in set(meta["jobs"])]
    store.close()
    if not records:
        raise InputError(f"{campaign_dir}: no finished jobs yet; run `adversary stress-test` first")
    gallery_count = meta["config"]["report"]["gallery"]
    results, timing = report_numbers(records, gallery_count)

    images = {"metrics": "figures/" + metrics_figure(results["comparison"], figures / "metrics.png"),
              "collision_types": None, "search": None}
    if any(r["total"] for r in results["collision_types"]):
        images["collision_types"] = "figures/" + collision_types_figure(
            results["collision_types"], figures / "collision_types.png")
    if results["search_history"]:
        images["search"] = "figures/" + search_figure(results["search_history"], figures / "search.png")
    from adversary.report.gallery import gallery_figures

    gallery = []
    for rank, worst in enumerate(results["worst"]):
        artifact = campaign_dir / "artifacts" / f"{worst['job_id']}.npz"
        if not artifact.is_file():
            continue
        title = (f"#{rank + 1} {short_spec(worst['planner'])} | {worst['env_id']} seed {worst['scene_seed']} "
                 f"episode {worst['episode']} | {worst['attack']}: {_outcome(worst)}")
        panel, strip = gallery_figures(artifact, worst["env_id"], figures, f"worst_{rank + 1}", title)
        gallery.append({**worst, "title": title, "panel": f"figures/{panel}", "strip": strip and f"figures/{strip}"})
    results["gallery_images"] = [{"job_id": g["job_id"], "panel": g["panel"], "strip": g["strip"]}
                                 for g in gallery]
    attacks = {a["label"] or a["name"]: a["name"] for a in meta["config"]["attacks"]}
    attack_notes = [{"label": label, "name": name, "category": attack_entry(name).category,
                     "summary": attack_entry(name).summary} for label, name in attacks.items()]
    report = {
        "campaign": {"name": meta["config"]["name"], "directory": str(campaign_dir),
                     "jobs_planned": len(meta["jobs"]), "jobs_finished": len(records)},
        "results": results, "timing": timing, "images": images,
        "config": meta["config"], "config_text": meta.get("config_text"),
        "campaign_provenance": {k: meta.get(k) for k in ("package_version", "git_commit")},
        "report_provenance": provenance(), "versions": versions(),
    }
    write_json(out_dir / "report.json", report)
    html = _environment().get_template("report.html.j2").render(
        r=report, gallery=gallery, attack_notes=attack_notes, collision_types=COLLISION_TYPES,
        config_json=json.dumps(meta["config"], indent=2))
    atomic_write(out_dir / "report.html", lambda f: f.write(html.encode()))
    return report
