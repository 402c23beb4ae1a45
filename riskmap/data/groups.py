"""Groups of recorded windows: the site and traffic configuration a demonstrator was recorded in
(`riskmap.data.collect_commonroad.recording_group`). Training and tuning split by group, never by
window, so one recorded moment of traffic is never on both sides."""

from __future__ import annotations

import re

from rasterize.errors import InputError
from riskmap.data.dataset import DemoDataset


def natural_key(name: str) -> list:
    """Sort key that orders `USA_US101-9` before `USA_US101-10`."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name)]


def match_groups(dataset: DemoDataset, groups: list[str], wanted: tuple[str, ...]) -> set[str]:
    """The dataset's `groups` named by `wanted`: full names, or configuration numbers matched
    against a name's `-N` suffix; InputError for one that names none."""
    chosen = set()
    for name in wanted:
        hits = [g for g in groups if g == name or g.endswith(f"-{name}")]
        if not hits and not groups:
            raise InputError(f"group {name}: dataset {dataset.root} has no groups (only recorded "
                             "data from `riskmap collect --from-commonroad` has); leave the groups "
                             "option out")
        if not hits:
            raise InputError(f"group {name}: dataset {dataset.root} has no such group; use one "
                             f"of {', '.join(groups)}")
        chosen.update(hits)
    return chosen


def dataset_groups(dataset: DemoDataset) -> list[str]:
    """The recorded groups of a dataset in natural order (empty for simulated data)."""
    return sorted({g for g in map(dataset.group_of, range(len(dataset))) if g is not None},
                  key=natural_key)


def windows_of_groups(dataset: DemoDataset, groups: tuple[str, ...]) -> list[int]:
    """Indices of the dataset's windows in the recorded `groups` (`match_groups`)."""
    chosen = match_groups(dataset, dataset_groups(dataset), groups)
    return [i for i in range(len(dataset)) if dataset.group_of(i) in chosen]
