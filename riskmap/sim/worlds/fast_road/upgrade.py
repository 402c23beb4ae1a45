"""Upgrading a highway-env env's roads in place to the fast classes (`riskmap.sim.worlds.fast_road.roads`,
imported only once highway-env 1.12 is found)."""

from __future__ import annotations

import functools

SUPPORTED_HIGHWAY_ENV = "1.12."


def install(base_env) -> None:
    """Upgrade the road `base_env` (a highway-env env, unwrapped) has now and every road it builds
    on later resets, as soon as it is built (before the env places and warms up its traffic)."""
    for name in ("_make_road", "_create_road"):
        if callable(getattr(type(base_env), name, None)):
            setattr(base_env, name, functools.partial(_build_then_upgrade, base_env, name))
    if getattr(base_env, "road", None) is not None:
        upgrade_road(base_env.road)


def _build_then_upgrade(base_env, name: str, *args, **kwargs):
    result = getattr(type(base_env), name)(base_env, *args, **kwargs)
    if getattr(base_env, "road", None) is not None:
        upgrade_road(base_env.road)
    return result


def upgrade_road(road):
    """Turn `road` (a highway-env `Road` or `RegulatedRoad`, exactly) and its `RoadNetwork` into
    their fast subclasses, in place; anything else is left as it is. Returns `road`."""
    classes = _classes()
    if classes is None:
        return road
    if type(road) is classes["Road"]:
        road.__class__ = classes["FastRoad"]
    elif type(road) is classes["RegulatedRoad"]:
        road.__class__ = classes["FastRegulatedRoad"]
    else:
        return road
    if type(road.network) is classes["RoadNetwork"]:
        road.network.__class__ = classes["FastRoadNetwork"]
    return road


_CLASSES: dict | None = None
_UNSUPPORTED = False


def _classes() -> dict | None:
    global _CLASSES, _UNSUPPORTED
    if _CLASSES is not None or _UNSUPPORTED:
        return _CLASSES
    import importlib.metadata

    from highway_env.road.regulation import RegulatedRoad
    from highway_env.road.road import Road, RoadNetwork

    try:
        version = importlib.metadata.version("highway-env")
    except importlib.metadata.PackageNotFoundError:
        version = ""
    if not version.startswith(SUPPORTED_HIGHWAY_ENV):
        _UNSUPPORTED = True
        return None

    # The classes subclass highway-env's, which is imported only once episodes run.
    from riskmap.sim.worlds.fast_road.roads import FastRegulatedRoad, FastRoad, FastRoadNetwork

    _CLASSES = {"Road": Road, "RegulatedRoad": RegulatedRoad, "RoadNetwork": RoadNetwork,
                "FastRoad": FastRoad, "FastRegulatedRoad": FastRegulatedRoad,
                "FastRoadNetwork": FastRoadNetwork}
    return _CLASSES
