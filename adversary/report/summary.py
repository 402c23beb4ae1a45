"""The report's opening paragraph, written from its numbers (numbers.py's by-family rows, whose
collision rates carry 95% Wilson intervals): which planner fails where and how often, against
its natural episodes, and whether the intervals are narrow enough to rank the planners.

Planners are compared only within one (scenario family, attack) cell, on the same scenes: one
collides more often than another when their intervals are disjoint. Where every compared pair
overlaps, the paragraph says that the intervals are too wide to rank, with the number of jobs per
cell. No number is computed here that the tables do not show.

The paragraph is written for one metric of the rows: "failure_rate", the failures that count
(valid, avoidable, at fault; the report's headline), or "collision_rate", every collision.
"""

from __future__ import annotations

from collections import defaultdict
from itertools import permutations

import numpy as np

from adversary.report.numbers import planner_name

MAX_RANKED = 3            # disjoint pairs spelt out; the rest are counted
MAX_PLACES = 3            # cells named where a planner collides most
# The paragraph's words for each metric it can be written for.
WORDS = {
    "collision_rate": {"did": "collided", "never": "never collided", "more": "collides more often than",
                       "none": "No planner collided in any of the {jobs} finished jobs."},
    "failure_rate": {"did": "failed", "never": "never failed", "more": "fails more often than",
                     "none": "No planner had a failure that counts in any of the {jobs} finished jobs."},
}


def _pct(stat: dict) -> str:
    return f"{100 * stat['value']:.0f}% [{100 * stat['lo']:.0f}, {100 * stat['hi']:.0f}]"


def _cell(row: dict, metric: str) -> str:
    stat = row[metric]
    return f"{_pct(stat)} ({stat['k']}/{stat['n']})"


def _where(row: dict) -> str:
    return f"under {row['attack']} on {row['family']}"


def _and(words: list[str]) -> str:
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} and {words[-1]}"


def _places(rows: list[dict]) -> str:
    """"under A and B on highway" (or "under A on highway and intersection") for the cells
    `rows` (at most MAX_PLACES named)."""
    shown, more = rows[:MAX_PLACES], len(rows) - MAX_PLACES
    families = list(dict.fromkeys(r["family"] for r in shown))
    attacks = list(dict.fromkeys(r["attack"] for r in shown))
    if len(families) == 1:
        text = f"{_and(attacks)} on {families[0]}"
    elif len(attacks) == 1:
        text = f"{attacks[0]} on {_and(families)}"
    else:
        text = ", ".join(f"{r['attack']} on {r['family']}" for r in shown)
    return f"under {text}" + (f" and {more} more" if more > 0 else "")


def _planner_sentence(rows: list[dict], categories: dict, first: bool, metric: str) -> str:
    name, words = planner_name(rows[0]), WORDS[metric]
    k = sum(r[metric]["k"] for r in rows)
    n = sum(r[metric]["n"] for r in rows)
    if k == 0:
        upper = max(r[metric]["hi"] for r in rows)
        return (f"{name} {words['never']} in its {n} jobs (yet the widest interval still reaches "
                f"{100 * upper:.0f}%).")
    top = max(r[metric]["value"] for r in rows)
    worst = [r for r in rows if r[metric]["value"] == top]
    alike = len({(r[metric]["k"], r[metric]["n"]) for r in worst}) == 1
    if alike:
        where = f"{_places(worst)} ({_pct(worst[0][metric])}, " \
                f"{worst[0][metric]['k']}/{worst[0][metric]['n']}" \
                f"{' each' if len(worst) > 1 else ''})"
    else:
        where = "under " + ", ".join(f"{r['attack']} on {r['family']} ({_cell(r, metric)})"
                                     for r in worst[:MAX_PLACES])
    baseline = [r for r in rows if categories.get(r["attack"]) == "baseline" and r not in worst]
    against = "; ".join(f"{_cell(r, metric)} {r['attack']} on {r['family']}" for r in baseline)
    start = f"{name} fails most: it {words['did']}" if first else f"{name} {words['did']}"
    return (f"{start} in {k} of its {n} jobs, most often {where}"
            + (f", against {against}." if against else "."))


def _ranking(cells: list[dict], metric: str) -> list[str]:
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in cells:
        groups[r["family"], r["attack"]].append(r)
    compared = {key: rows for key, rows in groups.items() if len(rows) >= 2}
    ns = sorted(r[metric]["n"] for r in cells)
    n_text = f"{ns[0]}" if ns[0] == ns[-1] else f"{ns[0]} to {ns[-1]}"
    width = 100 * float(np.median([r[metric]["hi"] - r[metric]["lo"] for r in cells]))
    if not compared:
        return [("Every scenario family and attack ran a single planner, so no two planners were "
                 "compared on the same scenes.")]
    disjoint, pairs = [], 0
    for (family, attack), rows in sorted(compared.items()):
        for a, b in permutations(rows, 2):
            if a["planner"] < b["planner"]:
                pairs += 1
            if a[metric]["lo"] > b[metric]["hi"]:
                disjoint.append((a, b))
    if not disjoint:
        return [(f"The intervals are too wide to rank the planners: with {n_text} jobs per planner, "
                 f"attack and family, a 95% interval spans {width:.0f} points (median), and every "
                 f"pair of planners run on the same family and attack overlaps; more episodes per "
                 f"scene family would be needed to separate them.")]
    said = [f"{planner_name(a)} {WORDS[metric]['more']} {planner_name(b)} "
            f"{_where(a)} ({_pct(a[metric])} against {_pct(b[metric])}, "
            f"intervals disjoint)" for a, b in disjoint[:MAX_RANKED]]
    more = len(disjoint) - MAX_RANKED
    text = "Ranked with confidence: " + "; ".join(said) + (f"; and {more} more such pairs" if more > 0 else "")
    out = [text + "."]
    if pairs > len(disjoint):
        out.append(f"The other {pairs - len(disjoint)} of {pairs} pairs compared overlap and cannot be "
                   f"ranked ({n_text} jobs per cell; intervals span {width:.0f} points on median).")
    return out


def summary_paragraph(by_family: list[dict], categories: dict[str, str], failed: int = 0,
                      metric: str = "collision_rate") -> dict:
    """{"text": the paragraph, "sentences": its sentences, "ranked": whether any two planners
    could be ranked} from numbers.py's by-family rows, written for `metric` (module docstring);
    `categories` maps attack labels to their category (the "baseline" ones are the natural
    episodes a planner's worst case is set against)."""
    cells = [r for r in by_family if r.get(metric) is not None]
    if not cells:
        sentences = ["No job finished, so there is nothing to summarise."]
        return {"text": sentences[0], "sentences": sentences, "ranked": False}
    by_planner: dict[str, list[dict]] = defaultdict(list)
    for r in cells:
        by_planner[r["planner"]].append(r)
    worst = {p: max(r[metric]["value"] for r in rows) for p, rows in by_planner.items()}
    share = {p: sum(r[metric]["k"] for r in rows) / sum(r[metric]["n"] for r in rows)
             for p, rows in by_planner.items()}
    # Who fails most: the highest rate in a cell, then the larger share of all its jobs.
    order = sorted(by_planner, key=lambda p: (-worst[p], -share[p], p))
    jobs = sum(r[metric]["n"] for r in cells)
    sentences = []
    if max(worst.values()) == 0:
        sentences.append(WORDS[metric]["none"].format(jobs=jobs))
    # "fails most" only for a planner ahead of the next one (not for a tie)
    alone = worst[order[0]] > 0 and (len(order) == 1 or (worst[order[0]], share[order[0]])
                                     != (worst[order[1]], share[order[1]]))
    sentences += [_planner_sentence(by_planner[p], categories, i == 0 and alone, metric)
                  for i, p in enumerate(order)]
    ranking = _ranking(cells, metric)
    sentences += ranking
    if failed:
        sentences.append(f"{failed} job{'s' if failed > 1 else ''} failed and "
                         f"{'are' if failed > 1 else 'is'} not counted.")
    return {"text": " ".join(sentences), "sentences": sentences,
            "ranked": ranking[0].startswith("Ranked")}
