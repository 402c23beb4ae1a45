"""How a Scene is cut from a CommonRoad recording (`CommonRoadSceneConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from rasterize.config import Extent
from rasterize.errors import InputError
from rasterize.highway import RouteRule
from rasterize.timebase import FUTURE_S, HISTORY_S, PLAN_DT_S


@dataclass(frozen=True)
class CommonRoadSceneConfig:
    """How a Scene is cut from a recording. Seconds, metres, metres/second."""

    history_s: float = HISTORY_S
    future_s: float = FUTURE_S
    dt_s: float = PLAN_DT_S           # the toolkit's window rate (2 Hz)
    radius_m: float = 120.0           # agents farther than this from the ego are left out
    max_agents: int = 32              # the ego included
    lane_radius_m: float = 260.0      # lanelets whose centre line comes this close are kept
    # The route rule's speed limit when the file gives none: 65 mph, the US-101 / I-80 limit.
    speed_limit_mps: float = 29.06
    route_rule: RouteRule = field(default_factory=RouteRule)
    # Signals whose stop line lies in this ego-centred rectangle are in the scene (the raster's
    # extent); None: those within `lane_radius_m` of the ego.
    extent: Extent | None = None
    # At a red light the goal point is held this far before the stop line (`red_light_hold`).
    stop_gap_m: float = 2.0

    def __post_init__(self) -> None:
        for name in ("history_s", "future_s", "stop_gap_m"):
            if not getattr(self, name) >= 0:
                raise InputError(f"CommonRoadSceneConfig.{name} must be >= 0")
        for name in ("dt_s", "radius_m", "lane_radius_m", "speed_limit_mps"):
            if not getattr(self, name) > 0:
                raise InputError(f"CommonRoadSceneConfig.{name} must be positive")
        if self.max_agents < 1:
            raise InputError("CommonRoadSceneConfig.max_agents must be at least 1")

    @property
    def history_steps(self) -> int:
        return round(self.history_s / self.dt_s)

    @property
    def future_steps(self) -> int:
        return round(self.future_s / self.dt_s)
