"""Whether envs are made fast (RISKMAP_FAST_ROAD), and whether a road is a fast one."""

from __future__ import annotations

import os

ENV_VAR = "RISKMAP_FAST_ROAD"


def fast_by_default() -> bool:
    """Whether envs are made fast when the caller does not say (RISKMAP_FAST_ROAD, default on)."""
    return os.environ.get(ENV_VAR, "1").strip().lower() not in ("0", "false", "no", "off")


def is_fast(road) -> bool:
    """Whether `road` is an upgraded road."""
    return bool(getattr(road, "fast_road", False))
