"""What every scenario source gives `riskmap.evaluation.evaluate` (the package docstring says how
the sources fit together), and the helpers both sources share."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

from riskmap.registry import cached_planner, display_name

# Columns of the common table that only some sources fill ("–" elsewhere).
OPTIONAL_COLUMNS = ("jerk_mps3", "human_distance_m", "red_light_violations")


class Scenario(Protocol):
    """One episode's world, driven once per planner."""

    @property
    def id(self) -> str:
        """Stable: names the episode's record file, so `--resume` finds finished work by it."""

    @property
    def label(self) -> int | str:
        """What episodes.csv's `episode` column shows."""

    def prepared(self, out: Path) -> bool:
        """Whether the recorded log is ready (so `prepare` need not run)."""

    def prepare(self, out: Path) -> None:
        """Make the recorded log under `out` once, before any planner drives (a no-op where the
        scenario already is a recording)."""

    def recorded_log(self, out: Path):
        """The log the planners are compared with (and `replay` plays back)."""

    def drive(self, spec: str, out: Path) -> dict:
        """One episode of planner SPEC, run by the source's existing world; the record to store."""

    def row(self, spec: str, record: dict) -> dict:
        """A stored record in the common per-episode layout (evaluate.CSV_FIELDS and what
        `summarise` reads: planner, label, episode, mode, failure, the metrics)."""


class ScenarioSource(Protocol):
    """Where a run's scenarios come from, and what of the run depends on that."""

    kind: str                       # results.json's "source"
    route_rule: str                 # what the planners drive towards (shown in the table's title)
    applies: frozenset[str]         # which of OPTIONAL_COLUMNS its records fill
    may_change: tuple[str, ...]     # settings keys (dotted) that `--resume` may change
    differs: str                    # how `--resume` with other settings is refused

    def scenarios(self) -> Sequence[Scenario]:
        """In a fixed order: the CSV and the summaries follow it."""

    def check(self, planners: tuple[str, ...]) -> None:
        """InputError for a planner this source cannot run, before anything is written."""

    def settings(self, planners: tuple[str, ...]) -> dict:
        """run.json's content (what `--resume` compares) and results.json's head."""

    def title(self) -> str:
        """The table's first line."""

    def where(self, row: dict) -> str:
        """Names an episode in messages (the first implausible plan's)."""


def planner_label(spec: str) -> str:
    """The Table I name of a planner SPEC (the paper's row names; other planners: their
    display name)."""
    kind = spec.partition(":")[0].replace("-", "_")
    return {"idm": "Human", "replay": "Replay", "cv": "CV", "riskmap": "Risk-aware (ours)",
            "cnn": "CNN", "cnn_lstm": "CNN-LSTM", "rvsg": "RvS-G"}.get(kind) or display_name(spec)

def worker_planner(spec: str, seed: int, goal_variance: float | None = None):
    """This process's planner for `spec` (one torch thread: workers run side by side)."""
    import torch

    torch.set_num_threads(1)
    return cached_planner(spec, seed, goal_variance)
