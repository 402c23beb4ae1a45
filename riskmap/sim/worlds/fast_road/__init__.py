"""A faster highway-env road: the same vehicle states every step, bit for bit, in less time.

highway-env answers its road's questions by brute force in Python, every simulation step: every
vehicle is tested against every other for a collision (`Road.step`), every neighbour search
projects every vehicle onto the lane (`Road.neighbour_vehicles`), every lane look-up measures the
distance to every lane of the network (`RoadNetwork.get_closest_lane_index`), and the
intersection's right-of-way rule predicts both vehicles of every pair again
(`RegulatedRoad.is_conflict_possible`, asked by `enforce_road_rules` for each pair).
`upgrade_road` turns one road and its network into subclasses that give the same answers
without the work whose outcome is known beforehand. Every vehicle still decides with its own
`act`, and the road's rules are still highway-env's `enforce_road_rules`; what changes is how
the road and its lanes answer what those ask:

- act window: while the road's vehicles act (`Road.act`) nobody moves, turns or changes speed
  (checked after every `act`: a vehicle that does raises an error instead of going unnoticed).
  Meanwhile the network's lanes remember their `local_coordinates` answers (per position, by
  its bytes; highway-env's own method computes each once), and the remembering is removed when
  the vehicles are done.
- neighbours: a search asked while a plain `IDMVehicle` acts is answered from the lane's list
  of members, made once per window with highway-env's coordinates and `on_lane` test (vehicles
  that cannot be on a straight lane, by their coordinates in floats with a margin, are not
  projected) and sorted along the lane, so that the nearest ahead and behind are found by
  bisection, with highway-env's choice among equals. Every other vehicle's searches are
  highway-env's own (its code may show the road other vehicles for a moment, as
  `adversary.search.perceived_idm` does).
- collisions: pairs whose bounding circles cannot meet (highway-env's own first test, with a
  margin against rounding) are skipped; highway-env's `handle_collisions` runs for the others,
  in highway-env's order.
- closest lane: lanes are visited in the order of a lower bound of their distance and bounded
  from above in floats; only the lanes that may be the closest are measured by highway-env's own
  `distance_with_heading`, and the first smallest wins as in highway-env (`_LaneFinder`).
- right of way: during one `enforce_road_rules` each vehicle's trajectory is predicted once
  instead of once per pair (straight stretches with numpy's elementwise arithmetic, the
  arithmetic of `StraightLane.position`), the distances of all pairs at all predicted times come
  from one numpy computation, pairs that never come within the circle test's distance are
  answered at once, and rectangle tests whose answer is clear beyond rounding are not run
  (`_rectangles_known`; highway-env's `rotated_rectangles_intersect` answers the others). A pair
  the shortcuts cannot settle is left to highway-env's `is_conflict_possible` (`_RuleCheck`).
- outside highway-env, for a fast road: the recorder's route ahead is computed only when a scene
  asks for it, from copies of what it reads (`rasterize.highway._RouteLater`), with straight
  lanes sampled at once (`positions_along_route`), and so are the lanes of a scene
  (`rasterize.highway.lanes_near`); the smallest gap around the ego (`min_gap_on_road`) measures
  boxes nearest first while a lower bound can still beat the smallest gap found.

Nothing is approximated: every value that reaches a vehicle, a record or a scene is computed by
the same operations on the same numbers as before; floats only decide what need not be
computed, always with a margin far beyond rounding. `tests/riskmap/sim/test_fast_road.py`
drives the same seeds with and without the upgrade and requires equal states, crashes, gaps,
routes and scenes, and compares the neighbour searches and the right-of-way pair test with
highway-env's on random scenes.

Switch: `riskmap.sim.worlds.episode.make_env(env_id, fast=False)` builds a plain highway-env env, and
so does the environment variable RISKMAP_FAST_ROAD=0 for every env made without an explicit
`fast`. Only highway-env 1.12's `Road` and `RegulatedRoad` (exactly those classes) are upgraded,
since the shortcuts rely on what that version's methods compute; any other road is left as it is.

Modules: `switch` (the switch, `is_fast`), `upgrade` (`install`, `upgrade_road`), `roads` (the
classes; imports highway-env), `lanes` (the closest-lane search), `act_window`, `collisions`,
`right_of_way`, `gaps` (`min_gap_on_road`), `tolerances` (the rounding margins).
"""

from riskmap.sim.worlds.fast_road.gaps import min_gap_on_road
from riskmap.sim.worlds.fast_road.switch import ENV_VAR, fast_by_default, is_fast
from riskmap.sim.worlds.fast_road.upgrade import SUPPORTED_HIGHWAY_ENV, _classes, install, upgrade_road

__all__ = ["ENV_VAR", "SUPPORTED_HIGHWAY_ENV", "fast_by_default", "install", "is_fast", "min_gap_on_road",
           "upgrade_road"]


def __getattr__(name: str):
    # The classes subclass highway-env's, which is imported only once episodes run.
    classes = _classes() or {}
    if name in ("FastRoad", "FastRegulatedRoad", "FastRoadNetwork") and name in classes:
        return classes[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
