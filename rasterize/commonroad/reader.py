"""Reading CommonRoad scenario files (`load_scenario`), through `rasterize.commonroad_compat`."""

from __future__ import annotations

import logging
import warnings
from pathlib import Path

import numpy as np

from rasterize.errors import InputError


def load_scenario(path: str | Path):
    """The `commonroad.scenario.scenario.Scenario` in an XML file (InputError if unreadable)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"CommonRoad file {path} does not exist; pass an existing scenario .xml")
    try:
        # The XML reader alone (why: rasterize.commonroad_compat), from the one module that
        # knows where each supported commonroad-io release keeps its classes.
        from rasterize.commonroad_compat import XMLFileReader
    except ImportError:
        raise InputError("reading CommonRoad files needs the commonroad-io package (2024.3 to "
                         "2026.x); install it as docs/guide/collect.md, `riskmap collect "
                         "--from-commonroad`, says") from None
    try:
        # commonroad-io logs a warning per old-style lanelet successor tag ("successorRight ...
        # is of deprecated format"): hundreds per Lankershim file, none of them actionable.
        logging.getLogger(XMLFileReader.__module__).setLevel(logging.ERROR)
        with warnings.catch_warnings():
            # shapely warns (on stderr) about NaN coordinates; they are refused just below
            warnings.simplefilter("ignore", RuntimeWarning)
            scenario, _ = XMLFileReader(str(path)).open()
    except Exception as err:  # noqa: BLE001 - any parse failure is a bad file for the user
        raise InputError(f"CommonRoad file {path} could not be read ({type(err).__name__}: "
                         f"{str(err).splitlines()[0] if str(err) else ''}); pass a valid scenario "
                         "file") from None
    for lanelet in scenario.lanelet_network.lanelets:
        for bound in (lanelet.left_vertices, lanelet.right_vertices, lanelet.center_vertices):
            if not np.isfinite(np.asarray(bound, dtype=float)).all():
                raise InputError(f"CommonRoad file {path}: lanelet {lanelet.lanelet_id} has NaN or inf "
                                 "points; repair its map or leave the file out")
    return scenario
