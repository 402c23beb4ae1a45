"""Raster and grid configurations, and the extent chosen for each scenario family.

Both the BEV raster and the risk-map grid cover the same ego-centred rectangle (an `Extent`);
they differ only in how finely it is divided. Cells need not be square: a highway extent is long
and narrow so that it covers where the ego can be in 6 s at highway speed without wasting most of
the grid on the verges.
"""

from __future__ import annotations

import numbers
from dataclasses import asdict, dataclass

from rasterize.errors import InputError
from rasterize.timebase import HISTORY_S


@dataclass(frozen=True)
class Extent:
    """Ego-centred rectangle, metres from the ego's centre: ahead, behind, to the left, right."""

    front_m: float
    back_m: float
    left_m: float
    right_m: float

    def __post_init__(self) -> None:
        for name in ("front_m", "back_m", "left_m", "right_m"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0):
                raise InputError(
                    f"extent {name}={value!r} does not contain the ego: every side of the extent "
                    "must be a positive distance in metres from the ego's centre"
                )

    @property
    def length_m(self) -> float:
        return self.front_m + self.back_m

    @property
    def width_m(self) -> float:
        return self.left_m + self.right_m


@dataclass(frozen=True)
class _Division:
    """An extent divided into rows (front to back) and columns (left to right)."""

    extent: Extent
    rows: int
    cols: int

    def __post_init__(self) -> None:
        if isinstance(self.extent, dict):
            object.__setattr__(self, "extent", Extent(**self.extent))
        for name in ("rows", "cols"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 2):
                raise InputError(f"{type(self).__name__}.{name}={value!r}: must be an integer >= 2")

    @property
    def row_m(self) -> float:
        """Metres per row (longitudinal size of a cell)."""
        return self.extent.length_m / self.rows

    @property
    def col_m(self) -> float:
        """Metres per column (lateral size of a cell)."""
        return self.extent.width_m / self.cols

    def to_dict(self) -> dict:
        return asdict(self)


MAX_PREDICT_S = 10.0


def check_predict_s(value, name: str = "RasterConfig.predict_s") -> None:
    """InputError unless `value` is a finite number of seconds in [0, MAX_PREDICT_S]."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not 0.0 <= value <= MAX_PREDICT_S:   # NaN fails the comparison too
        raise InputError(f"{name}={value!r}: must be seconds of predicted future in "
                         f"[0, {MAX_PREDICT_S:g}] (0 draws none)")


@dataclass(frozen=True)
class RasterConfig(_Division):
    """The BEV raster: `rows` x `cols` pixels over `extent`, history drawn over `history_s`.

    `predict_s` > 0 adds the predicted future over that many seconds (`rasterize.raster.channels`);
    0, the default and what configs saved before it existed load as, draws the 8 base channels.
    """

    rows: int = 200
    cols: int = 200
    history_s: float = HISTORY_S
    predict_s: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.history_s >= 0:
            raise InputError(f"RasterConfig.history_s={self.history_s!r}: must be >= 0 seconds")
        check_predict_s(self.predict_s)
        object.__setattr__(self, "predict_s", float(self.predict_s))   # JSON-safe in sidecars

    @classmethod
    def from_dict(cls, data: dict) -> RasterConfig:
        return cls(**data)

    def grid(self, resolution: int) -> GridConfig:
        """The risk-map grid of `resolution` x `resolution` cells over the same extent."""
        return GridConfig(self.extent, resolution, resolution)


@dataclass(frozen=True)
class GridConfig(_Division):
    """The risk-map grid: `rows` x `cols` cells over `extent`."""

    rows: int = 50
    cols: int = 50

    @classmethod
    def from_dict(cls, data: dict) -> GridConfig:
        return cls(**data)


# Extents per scenario family. Each covers where the ego can be 6 s ahead (the plan horizon) at
# the family's speeds, with room for a lane change either side and for the agents behind that
# can still reach the ego:
#   highway:      ego speeds up to ~33 m/s -> 6 s x 33 m/s = 198 m ahead; 4 lanes of 4 m -> the
#                 farthest lane centre is 12 m away laterally. 200 m ahead, 40 m behind, 20 m a side.
#   merge:        same speeds as highway plus the on-ramp below the main road.
#   roundabout:   ego speeds up to ~16 m/s -> 96 m of path, but it curls round a ring of radius
#                 ~20 m; 70 m ahead, 30 m behind and 50 m a side hold the ring and its exits.
#   intersection: ego speeds up to ~10 m/s -> 60 m; turns reach 40 m sideways within 6 s.
FAMILY_EXTENTS: dict[str, Extent] = {
    "highway": Extent(front_m=200.0, back_m=40.0, left_m=20.0, right_m=20.0),
    "merge": Extent(front_m=200.0, back_m=40.0, left_m=25.0, right_m=25.0),
    "roundabout": Extent(front_m=70.0, back_m=30.0, left_m=50.0, right_m=50.0),
    "intersection": Extent(front_m=60.0, back_m=20.0, left_m=40.0, right_m=40.0),
}

ENV_FAMILIES: dict[str, str] = {
    "highway-v0": "highway",
    "highway-fast-v0": "highway",
    "merge-v0": "merge",
    "roundabout-v0": "roundabout",
    "intersection-v0": "intersection",
}


def family_of_env(env_id: str) -> str:
    """The scenario family of a highway-env id, or an InputError listing the supported ids."""
    try:
        return ENV_FAMILIES[env_id]
    except KeyError:
        raise InputError(
            f"unknown env {env_id!r}; choose one of {', '.join(sorted(ENV_FAMILIES))}"
        ) from None


def raster_config_for_env(env_id: str, rows: int = 200, cols: int = 200) -> RasterConfig:
    return RasterConfig(FAMILY_EXTENTS[family_of_env(env_id)], rows, cols)
