"""The guard's result tables, in one form: decision frames and interventions summed over driven
records, the BDI intervention ratio as a table cell, a markdown table of cells, and a table printed and optionally written
as PREFIX.json (the rows) and PREFIX.md (the markdown). Records are dicts with an optional
"guard" entry holding the guard's summary (`frames`, `interventions`), as the guard's closed-loop
drives and the re-drives of attack records (`adversary.crash.redrive`) write them."""

from __future__ import annotations

from pathlib import Path

from riskmap.infra.atomic import atomic_write, write_json


def intervention_totals(records: list[dict]) -> dict:
    """Decision frames and System 2 take-overs summed over the records driven with a guard, and the
    BDI intervention ratio (None where no decision frame was recorded: no guard, or it never ran)."""
    frames = sum(r["guard"]["frames"] for r in records if "guard" in r)
    interventions = sum(r["guard"]["interventions"] for r in records if "guard" in r)
    return {"frames": frames, "interventions": interventions,
            "intervention_ratio": interventions / frames if frames else None}


def ratio_cell(row: dict) -> str:
    """A row's BDI intervention ratio as a table cell ("–" where it has none)."""
    return f"{row['intervention_ratio']:.3f}" if row["intervention_ratio"] is not None else "–"


def markdown_table(columns, rows) -> str:
    """A markdown table: the header of `columns`, its rule, then one line per row of `rows` (each a
    sequence of cells, written as `str` writes them), newline-terminated."""
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def print_table(rows: list[dict], markdown, prefix: Path | None) -> None:
    """Print the markdown table of `rows` (`markdown(rows)`); with a `prefix`, also write
    PREFIX.json (the rows) and PREFIX.md (the table)."""
    if prefix is not None:
        write_json(prefix.with_suffix(".json"), rows)
        atomic_write(prefix.with_suffix(".md"), lambda f: f.write(markdown(rows).encode()))
    print(markdown(rows))
