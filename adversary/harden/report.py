"""The page of a hardening run (RUN/report.html, RUN/report.md): per round, fresh CRASH on held-out
scenes with 95% Wilson intervals, the failures that count (valid, avoidable, at fault;
`riskmap.sim.records.failures`) first and every win beside them, natural-traffic metrics, and one attacked scene's risk
map planned by the original and by the last round's planner (RUN/report/*.png)."""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

from rasterize.errors import InputError
from riskmap.infra.atomic import atomic_write
from riskmap.infra.stats import wilson

PANEL_CANDIDATES = 80      # attack windows searched for the before/after panel
COLUMNS = ("round", "fresh CRASH: valid avoidable at-fault failures [95% CI]", "fresh CRASH: every win [95% CI]",
           "training attacks won",
           "training search failures", "adversarial windows", "natural collisions", "natural progress (m)",
           "open-loop ADE (m)")


def _rate(hits: int | None, n: int | None) -> str:
    if hits is None or not n:
        return "–"
    ci = wilson(hits, n)
    return f"{hits}/{n} ({100 * hits / n:.0f}% [{100 * ci['lo']:.0f}–{100 * ci['hi']:.0f}])"


def round_row(entry: dict) -> tuple[str, ...]:
    judged = entry.get("judged", {})
    fresh = judged.get("attack") or {}
    trained = entry.get("training_attack") or {}
    natural = judged.get("closed_loop") or {}
    ade = (judged.get("open_loop") or {}).get("ade_m", {}).get("mean")
    windows = (entry.get("data") or {}).get("attack_windows")      # CRASH's and the search's
    searched = entry.get("training_search") or {}
    counted = (fresh.get("failures") or {}).get("counted")     # None: judged before the classification
    return (str(entry["round"]), _rate(counted, fresh.get("scenes")), _rate(fresh.get("collisions"), fresh.get("scenes")),
            _rate(trained.get("collisions"), trained.get("scenes")) if trained else "–",
            "; ".join(f"{t} {v['collisions']}/{v['evaluations']}" for t, v in sorted(searched.items())) or "–",
            "–" if windows is None else str(windows),
            _rate(natural.get("collisions"), natural.get("episodes")),
            "–" if natural.get("distance_m") is None else f"{natural['distance_m']:.1f}",
            "–" if ade is None else f"{ade:.2f}")


def before_after(run: Path, rounds: list[dict]) -> list[tuple[str, Path]]:
    """One attack window of round 1 planned by round 0's and the last round's planner (PNG rows)."""
    from adversary.harden.loop import round_dir
    from riskmap.data.dataset import DemoDataset
    from riskmap.figures.panels import save_plan_panels
    from riskmap.planner.riskmap_planner import load_planner

    settings = json.loads((run / "harden.json").read_text())
    last = max(e["round"] for e in rounds)
    data = round_dir(run, 1) / "data"
    if last < 1 or not data.exists():
        return []
    dataset = DemoDataset(data)
    adversarial = [i for i in range(len(dataset)) if dataset.group_of(i) == "adversarial"]
    if not adversarial:
        return []
    # The window where the original plans furthest beyond the demonstrated alternative (it
    # would have driven on where the demonstration gives way): where hardening should show.
    original = load_planner(Path(settings["checkpoint"]), seed=0)
    picks = [adversarial[int(k)] for k in np.unique(np.linspace(0, len(adversarial) - 1,
                                                                 min(PANEL_CANDIDATES, len(adversarial))).astype(int))]

    def overshoot_m(i: int) -> float:
        scene = dataset.scene(i)
        demo = float(np.linalg.norm(scene.ego_future_xy()[-1] - scene.ego_state()[:2]))
        return float(np.linalg.norm(original.plan(scene).waypoints[-1])) - demo

    window = max(picks, key=overshoot_m)
    scene = dataset.scene(window)
    out = []
    for r, checkpoint in ((0, Path(settings["checkpoint"])), (last, round_dir(run, last) / "planner")):
        planner = original if r == 0 else load_planner(checkpoint, seed=0)
        plan = planner.plan(scene)
        path = run / "report" / f"before_after_round_{r}.png"
        save_plan_panels(scene, plan, planner.raster, planner.grid, path,
                         f"round {r} planner on attack window {window} of round 1 (demonstration: the "
                         "collision-free alternative)")
        out.append((f"round {r}", path))
    return out


def write_report(run: Path) -> Path:
    """Write RUN/report.md and RUN/report.html from RUN/rounds.json; returns the HTML's path."""
    run = Path(run)
    try:
        rounds = json.loads((run / "rounds.json").read_text())["rounds"]
    except (OSError, ValueError, KeyError):
        raise InputError(f"{run} holds no rounds.json; run `adversary harden --out {run}` first") from None
    rows = [round_row(e) for e in rounds]
    figures = before_after(run, rounds)
    md = ["# Hardening rounds", "", "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    md += ["| " + " | ".join(r) + " |" for r in rows]
    md += ["", *[f"![{label}](report/{p.name})" for label, p in figures], ""]
    atomic_write(run / "report.md", lambda f: f.write("\n".join(md).encode()))
    cells = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows)
    head = "".join(f"<th>{html.escape(c)}</th>" for c in COLUMNS)
    images = "".join(f"<h3>{html.escape(label)}</h3><img src='report/{p.name}' style='max-width:100%'>"
                     for label, p in figures)
    page = (f"<!doctype html><html><head><meta charset='utf-8'><title>Hardening rounds</title>"
            "<style>body{font-family:sans-serif;margin:2em}td,th{border:1px solid #ccc;padding:4px 8px}"
            "table{border-collapse:collapse}</style></head><body><h1>Hardening rounds</h1>"
            f"<p>{html.escape(str(run))}: round 0 is the original planner; every round's planner is attacked "
            "afresh on the held-out scenes (CRASH, MAM+ASM).</p>"
            f"<table><tr>{head}</tr>{cells}</table><h2>The same attacked window, before and after</h2>"
            f"{images}</body></html>")
    atomic_write(run / "report.html", lambda f: f.write(page.encode()))
    return run / "report.html"
