"""The shipped planners by name: the SPEC (`riskmap.registry`) each one is in a scenario family.

The experiments compare the same three planners in every family: `replay` (the recorded human),
`idm` (rule-based, closed loop) and `riskmap` (the risk-aware planner of checkpoints/, one per
family). One catalogue, so that an attack run and the guard run built on it name the same planner.
"""

from __future__ import annotations

from rasterize.errors import InputError

FAMILIES = ("highway", "intersection", "us101")
SHIPPED_PLANNERS = {
    "replay": "replay",
    "idm": "idm",
    "riskmap": {family: f"riskmap:checkpoints/riskmap_{family}" for family in FAMILIES},
}


def shipped_spec(name: str, family: str) -> str:
    """The SPEC of the shipped planner `name` in `family` (highway, intersection, us101, or a
    highway-env id such as highway-v0)."""
    if name not in SHIPPED_PLANNERS:
        raise InputError(f"planner {name!r}: not shipped; one of {', '.join(SHIPPED_PLANNERS)}")
    spec = SHIPPED_PLANNERS[name]
    if isinstance(spec, str):
        return spec
    key = family.removesuffix("-v0")
    if key not in spec:
        raise InputError(f"planner {name!r}: no shipped checkpoint for family {family!r}; one of {', '.join(spec)}")
    return spec[key]
