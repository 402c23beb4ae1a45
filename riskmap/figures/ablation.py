"""What a planner ablation (experiments/ablation_*.py) writes, in one form: a progress line per
result row, the markdown table (OUT/table.md, also printed) and the summary figure (OUT/ablation.png)."""

from __future__ import annotations

from pathlib import Path


def print_row(row: dict) -> None:
    """The row as key=value pairs, floats to 4 significant digits; flushed, since each row of an
    ablation takes minutes and the line is its progress report."""
    print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()),
          flush=True)


def write_table(out: Path, lines: list[str]) -> None:
    """The markdown table `lines` to OUT/table.md, and to the terminal."""
    (out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def pyplot():
    """matplotlib's pyplot drawing to files only (the Agg backend): the scripts run without a display."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, out: Path, title: str) -> None:
    """`fig`, titled `title`, to OUT/ablation.png; the figure is closed."""
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "ablation.png")
    pyplot().close(fig)
