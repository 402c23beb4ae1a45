"""The report's opening paragraph from hand-made by-family rows: who fails where and how often,
and when the intervals are too wide to rank the planners."""

from adversary.report.summary import summary_paragraph
from riskmap.infra.stats import wilson

CATEGORIES = {"natural": "baseline", "aggressive_neighbour": "rule"}


def _row(planner, attack, k, n, family="highway"):
    return {"family": family, "planner": planner, "attack": attack, "jobs": n, "failed": 0,
            "collision_rate": wilson(k, n)}


def _pct(k, n):
    s = wilson(k, n)
    return f"{100 * s['value']:.0f}% [{100 * s['lo']:.0f}, {100 * s['hi']:.0f}] ({k}/{n})"


def test_few_jobs_per_cell_are_too_few_to_rank():
    rows = [_row("cv", "natural", 0, 3), _row("cv", "aggressive_neighbour", 2, 3),
            _row("idm", "natural", 0, 3), _row("idm", "aggressive_neighbour", 1, 3)]
    summary = summary_paragraph(rows, CATEGORIES)
    text = summary["text"]
    assert text.startswith("cv fails most: it collided in 2 of its 6 jobs, most often under "
                           "aggressive_neighbour on highway")
    assert _pct(0, 3) + " natural on highway" in text          # the worst case against natural
    assert "idm collided in 1 of its 6 jobs" in text
    assert "too wide to rank" in text and "with 3 jobs per planner" in text
    assert summary["ranked"] is False


def test_disjoint_intervals_rank_the_planners():
    rows = [_row("cv", "aggressive_neighbour", 40, 40), _row("idm", "aggressive_neighbour", 2, 40),
            _row("cv", "natural", 20, 40), _row("idm", "natural", 19, 40)]
    summary = summary_paragraph(rows, CATEGORIES)
    text = summary["text"]
    assert summary["ranked"] is True
    assert "Ranked with confidence: cv collides more often than idm under aggressive_neighbour on highway" in text
    assert "The other 1 of 2 pairs compared overlap" in text   # natural: 20/40 against 19/40


def test_no_collision_and_planners_never_compared():
    rows = [_row("cv", "natural", 0, 5, "highway"), _row("idm", "natural", 0, 5, "intersection")]
    text = summary_paragraph(rows, CATEGORIES, failed=1)["text"]
    assert text.startswith("No planner collided in any of the 10 finished jobs.")
    assert "cv never collided in its 5 jobs" in text
    assert "no two planners were compared on the same scenes" in text
    assert text.endswith("1 job failed and is not counted.")


def test_ties_name_every_worst_cell_and_nobody_fails_most():
    rows = [_row("a", "natural", 1, 2), _row("a", "aggressive_neighbour", 1, 2),
            _row("b", "natural", 1, 2), _row("b", "aggressive_neighbour", 1, 2)]
    text = summary_paragraph(rows, CATEGORIES)["text"]
    assert "fails most" not in text
    assert "a collided in 2 of its 4 jobs, most often under natural and aggressive_neighbour on " \
           "highway (50% [9, 91], 1/2 each)." in text


def test_nothing_finished():
    assert summary_paragraph([], CATEGORIES)["text"].startswith("No job finished")
