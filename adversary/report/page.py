"""`adversary report DIR`: report.html (Jinja2) + PNG figures + report.json from a campaign,
and a page per job (jobs/JOB_ID.html, its pictures under jobs/media/).

The page opens with the failures that count (valid, avoidable, at-fault collisions,
riskmap.sim.records.failures): a paragraph written from the numbers (adversary.report.summary) and their
rate per planner and attack with its intervals, every collision's rate beside it
(figures.headline_figure); the tables follow. The worst scenes that collided are animated (GIF, adversary.report.frames).

report.json holds every number on the page: "results" (a function of the records alone, so a
resumed or distributed campaign gives the same), "timing" (machine-dependent), the config,
versions and provenance, and "pages" (each job's page). Planners are shown by their display names
(riskmap.registry.display_names over the campaign's planners); report.json keeps each SPEC
("planner") beside its name ("planner_name").
"""

from __future__ import annotations

import json
import platform
from importlib import metadata
from pathlib import Path

from adversary.attacks.registry import attack_entry
from adversary.campaign.store import ResultStore
from adversary.report.figures import collision_types_figure, headline_figure, metrics_figure, search_figure
from adversary.report.jobs import job_media, job_page, job_title, outcome
from adversary.report.numbers import COLLISION_TYPES, report_numbers
from adversary.report.summary import summary_paragraph
from rasterize.errors import InputError
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.provenance import provenance
from riskmap.registry import display_names
from riskmap.sim.records.failures import failure_explanation, unknown_failure
from riskmap.sim.records.record import current_names

_PACKAGES = ("riskmap-toolkit", "numpy", "torch", "highway-env", "gymnasium", "scipy", "matplotlib",
             "jinja2", "pyyaml", "imageio", "pillow", "ray")


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


def _fmt_classes(classes) -> str:
    """valid / avoidable / at fault / struck from behind / side / unknown counts of the collisions
    (valid: "–" when no collision was an attack's)."""
    if not classes or not classes["collisions"]:
        return "–"
    valid = "–" if classes["valid"] is None else classes["valid"]
    return (f"{valid} / {classes['avoidable']} / {classes['at_fault']} / {classes['struck_from_behind']} / "
            f"{classes['side']} / {classes['unknown']} of {classes['collisions']}")


def failures_lead(rows: list[dict]) -> str:
    """The report's first sentence: how many of all collisions count (numbers.py's rows)."""
    classes = [r["failure_classes"] for r in rows if r.get("failure_classes")]
    total = {k: sum(c[k] or 0 for c in classes) for k in ("collisions", "unknown", "counted", "trials")}
    if not total["collisions"]:
        return f"No collision in {total['trials']} finished jobs."
    unknown = (f"; {total['unknown']} could not be classified (records written before the classification)"
               if total["unknown"] else "")
    return (f"Of {total['collisions']} collisions in {total['trials']} finished jobs, {total['counted']} count as "
            f"failures of the planner: at fault, avoidable by a driver reacting to what it could see, and, "
            f"where an adversary caused it, a valid attack{unknown}.")


def _environment():
    from jinja2 import Environment, PackageLoader, select_autoescape

    env = Environment(loader=PackageLoader("adversary.report", "templates"),
                      autoescape=select_autoescape(["html", "j2"]), trim_blocks=True,
                      lstrip_blocks=True)
    env.filters["rate"] = _fmt_rate
    env.filters["mean"] = _fmt_mean
    env.filters["classes"] = _fmt_classes
    return env


def make_report(campaign_dir: Path, out_dir: Path | None = None) -> dict:
    """Write report.html, report.json and the PNGs into out_dir (default: the campaign dir)."""
    campaign_dir = Path(campaign_dir)
    meta_path = campaign_dir / "campaign.json"
    if not meta_path.is_file():
        raise InputError(f"{campaign_dir}: no campaign.json; pass a directory written by "
                         "`adversary stress-test --out`")
    out_dir = Path(out_dir or campaign_dir)
    figures = out_dir / "figures"
    try:
        meta = json.loads(meta_path.read_text())
        if not {"jobs", "config"} <= set(meta) or "report" not in meta["config"]:
            raise ValueError("not a campaign.json")
    except (ValueError, TypeError):
        raise InputError(f"{meta_path} is damaged (not a campaign.json of `adversary stress-test`); "
                         "run the campaign again into a new --out") from None
    for path in sorted((campaign_dir / "records").glob("*.json")):
        try:
            if "job_id" not in json.loads(path.read_text()):
                raise ValueError("not a job record")
        except (ValueError, TypeError):
            raise InputError(f"record {path} is damaged; delete it and run `adversary stress-test "
                             f"--resume --out {campaign_dir}` to run that job again") from None
    store = ResultStore(campaign_dir)
    records = [r for r in store.records() if r["job_id"] in set(meta["jobs"])]
    store.close()
    if not records:
        raise InputError(f"{campaign_dir}: no finished jobs yet; run `adversary stress-test` first")
    gallery_count = meta["config"]["report"]["gallery"]
    figures.mkdir(parents=True, exist_ok=True)
    # the campaign's names (its config lists every planner in order), as its tables show them
    names = display_names([*meta["config"]["planners"], *(r["planner"] for r in records)])
    results, timing = report_numbers(records, gallery_count, names)
    attacks = {a["label"] or a["name"]: a["name"] for a in meta["config"]["attacks"]}
    categories = {label: attack_entry(name).category for label, name in attacks.items()}
    categories.update({r["attack"]: r["attack_category"] for r in records if "attack_category" in r})
    results["summary"] = {**summary_paragraph(results["by_family"], categories, results["failed"], "failure_rate"),
                          "lead": failures_lead(results["comparison"])}
    results["summary_collisions"] = summary_paragraph(results["by_family"], categories, results["failed"])

    images = {"headline": "figures/" + headline_figure(results["by_family"], list(attacks),
                                                        figures / "headline.png"),
              "metrics": "figures/" + metrics_figure(results["comparison"], figures / "metrics.png"),
              "collision_types": None, "search": None}
    if any(r["total"] for r in results["collision_types"]):
        images["collision_types"] = "figures/" + collision_types_figure(
            results["collision_types"], figures / "collision_types.png")
    if results["search_history"]:
        images["search"] = "figures/" + search_figure(results["search_history"], figures / "search.png")
    from adversary.report.gallery import gallery_panel

    # The worst scenes that collided are animated (their pages and the gallery show the GIF).
    animate = {w["job_id"] for w in results["worst"] if w["collided"]}
    media = {r["job_id"]: job_media(campaign_dir / "artifacts" / f"{r['job_id']}.npz",
                                    _named(current_names(r), names), out_dir, r["job_id"] in animate)
             for r in records}
    gallery = []
    for rank, worst in enumerate(results["worst"]):
        artifact = campaign_dir / "artifacts" / f"{worst['job_id']}.npz"
        if not artifact.is_file() or media[worst["job_id"]].get("unreadable"):
            continue
        title = f"#{rank + 1} {job_title(worst)}: {outcome(worst)}"
        panel = gallery_panel(artifact, worst["env_id"], figures, f"worst_{rank + 1}", title)
        m = media[worst["job_id"]]
        gallery.append({**worst, "title": title, "panel": panel and f"figures/{panel}",
                        "page": job_page(worst["job_id"]),
                        **{k: m[k] and f"jobs/{m[k]}" for k in ("strip", "gif")}})
    results["gallery_images"] = [{k: g[k] for k in ("job_id", "panel", "strip", "gif", "page")}
                                 for g in gallery]
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
    jobs = [{"job_id": r["job_id"], "page": job_page(r["job_id"]), "planner": r["planner"],
             "planner_name": names[r["planner"]],
             "env_id": r["env_id"], "scene_seed": r["scene_seed"], "episode": r["episode"],
             "attack": r["attack"], "status": r["status"], "outcome": outcome(current_names(r)),
             "animated": bool(media[r["job_id"]]["gif"]),
             # a recorded family's scene: its recording, vehicle and attack time
             **{k: r[k] for k in ("recording", "ego_id", "t0_s") if k in r}} for r in records]
    report["pages"] = {j["job_id"]: j["page"] for j in jobs}
    write_json(out_dir / "report.json", report)
    env = _environment()
    _write_job_pages(env, out_dir, records, media, {g["job_id"]: g for g in gallery}, gallery_count, names,
                     campaign_dir)
    html = env.get_template("report.html.j2").render(
        r=report, gallery=gallery, jobs=jobs, attack_notes=attack_notes, collision_types=COLLISION_TYPES,
        config_json=json.dumps(meta["config"], indent=2))
    atomic_write(out_dir / "report.html", lambda f: f.write(html.encode()))
    return report


def _named(record: dict, names: dict[str, str]) -> dict:
    """A copy of `record` with its planner's display name (the stored record stays as it is)."""
    return {**record, "planner_name": names[record["planner"]]}


def _write_job_pages(env, out_dir: Path, records: list[dict], media: dict, gallery: dict,
                     gallery_count: int, names: dict[str, str], campaign_dir: Path) -> None:
    """OUT/jobs/JOB_ID.html for every job: its pictures, its record as stored and, for a job
    `adversary export` can write as a CommonRoad scenario, the command that does."""
    from adversary.export.campaign import export_command

    template = env.get_template("job.html.j2")
    (out_dir / "jobs").mkdir(parents=True, exist_ok=True)
    for record in records:
        job_id = record["job_id"]
        entry = gallery.get(job_id)
        if media[job_id]["attack_panel"]:
            entry = entry and {**entry, "panel": None}     # the gallery's panel is the attack's own
        html = template.render(
            record=record, title=job_title(_named(record, names)), planner_name=names[record["planner"]],
            outcome=outcome(current_names(record)),
            failure_text=(failure_explanation(record.get("failure") or unknown_failure())
                          if record.get("collided") else None),
            media=media[job_id], panel=entry and entry["panel"] and f"../{entry['panel']}",
            rank=entry and entry["title"].split(" ", 1)[0], gallery_count=gallery_count,
            record_json=json.dumps(record, indent=2, sort_keys=True),
            export_command=export_command(campaign_dir, record, campaign_dir / "artifacts" / f"{job_id}.npz"))
        atomic_write(out_dir / job_page(job_id), lambda f, html=html: f.write(html.encode()))
