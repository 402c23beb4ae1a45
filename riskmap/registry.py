"""One parser for planner SPEC strings (DESIGN §2).

Built in:

    idm              the IDM/MOBIL "human": the ego drives itself, no plan is made
    yielding         IDM/MOBIL that gives way at conflict zones by gap acceptance (the
                     intersection teacher, `riskmap.sim.yielding`)
    cv               constant velocity: current speed and heading for 6 s
    riskmap:PATH     the risk-map planner from a checkpoint (PATH with or without .safetensors)
    guard:SPEC       SPEC wrapped in the neuro-symbolic guard, TGAT-triggered (`guarded:` too)
    guard-always:SPEC  SPEC with the guard's deceleration plan always on at high speed
    replay           log playback of the human's recorded trajectory (needs a recorded episode)
    cnn:PATH, cnn_lstm:PATH (or cnn-lstm:PATH), rvsg:PATH
                     behaviour-cloning baselines from `riskmap train-baseline` checkpoints

Plug-ins: any other `NAME:ARG` is looked up in the entry-point group `riskmap.planners`, whose
entry `NAME` is a factory `factory(ARG, seed=...)` returning a planner. The guard is one
(`guard`, `guarded`, `guard-always`, declared in pyproject.toml): it wraps a planner made by this
registry, so it sits above it and the registry never imports it.
"""

from __future__ import annotations

from rasterize.errors import InputError
from riskmap.sim.plan import HumanDriver

PLUGIN_GROUP = "riskmap.planners"
SPECS = ("idm", "yielding", "cv", "replay", "riskmap:PATH", "cnn:PATH", "cnn_lstm:PATH", "rvsg:PATH",
         "guard:SPEC", "guard-always:SPEC")


def make_planner(spec: str, seed: int = 0, goal_variance: float | None = None):
    """A `Planner` (or `HumanDriver`) for `spec`; `goal_variance` (cells²) overrides a risk-map
    checkpoint's planning-time goal variance."""
    kind, _, arg = spec.partition(":")
    if kind == "idm" and not arg:
        return HumanDriver()
    if kind == "yielding" and not arg:
        from riskmap.sim.yielding import demonstrator

        return demonstrator("yielding")
    if kind == "cv" and not arg:
        from riskmap.planner.baselines import ConstantVelocityPlanner

        return ConstantVelocityPlanner()
    if kind == "riskmap" and arg:
        from riskmap.planner.riskmap_planner import RiskMapPlanner

        return RiskMapPlanner.load(arg, seed=seed, goal_variance=goal_variance)
    if kind == "replay" and not arg:
        from riskmap.sim.log_replay import ReplayPlanner

        return ReplayPlanner()
    if kind in ("cnn", "cnn_lstm", "cnn-lstm", "rvsg") and arg:
        from riskmap.planner.bc import BCPlanner

        return BCPlanner.load(arg, expected_kind=kind)
    factory = _plugin(kind) if arg else None
    if factory is not None:
        return factory(arg, seed=seed)
    raise InputError(f"unknown planner spec {spec!r}; use one of {', '.join(SPECS)}")


def _plugin(name: str):
    """The factory of entry point `name` in group `riskmap.planners`, or None."""
    from importlib.metadata import entry_points

    for entry in entry_points(group=PLUGIN_GROUP, name=name):
        try:
            return entry.load()
        except ImportError as err:
            raise InputError(f"planner plug-in {name!r} ({entry.value}) cannot be imported ({err}); "
                             "install what it needs") from None
    return None


_CACHED: dict = {}


def cached_planner(spec: str, seed: int = 0, goal_variance: float | None = None):
    """`make_planner(spec, seed, goal_variance)`, made once per process: loading a checkpoint
    costs seconds, and a planner is reset at the start of every episode, so reuse does not
    change results."""
    key = (spec, seed, goal_variance)
    if key not in _CACHED:
        _CACHED[key] = make_planner(spec, seed=seed, goal_variance=goal_variance)
    return _CACHED[key]
