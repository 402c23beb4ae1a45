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

Your own planner, with no change to the toolkit:

    py:package.module:Factory[?key=value&...]
                     `Factory(key=value, ..., seed=SEED)` (seed only if it takes one), imported
                     from any module on the path or in the working directory; values are read
                     as int, finite float, true/false or text (URL-quoted where they hold `&`,
                     `=` or `?`)
    NAME:ARG         entry `NAME` of the entry-point group `riskmap.planners` (an installed
                     package declares it), called as `factory(ARG, seed=SEED)`

Either must return a planner (`riskmap.sim.plan.Planner`: `reset(scene)`, `plan(scene) -> Plan`,
or `drives_itself = True`); anything else is a one-line error naming the SPEC. The guard is an
entry-point plug-in (`guard`, `guarded`, `guard-always`, declared in pyproject.toml): it wraps a
planner made by this registry, so it sits above it and the registry never imports it.
"""

from __future__ import annotations

from rasterize.errors import InputError
from riskmap.sim.plan import HumanDriver

PLUGIN_GROUP = "riskmap.planners"
SPECS = ("idm", "yielding", "cv", "replay", "riskmap:PATH", "cnn:PATH", "cnn_lstm:PATH", "rvsg:PATH",
         "guard:SPEC", "guard-always:SPEC", "py:module:Factory[?key=value&...]")
# The one help text of every command-line flag that takes a planner SPEC.
SPEC_HELP = ("planner SPEC: idm, yielding, cv, replay (recordings), riskmap:PATH, cnn:PATH, "
             "cnn_lstm:PATH, rvsg:PATH, guard:SPEC, your own py:package.module:Factory[?key=value&...] "
             "or an installed plug-in NAME:ARG (README, \"Your own planner\")")


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
        from riskmap.planner.riskmap_planner import load_planner

        return load_planner(arg, seed=seed, goal_variance=goal_variance)
    if kind == "replay" and not arg:
        from riskmap.sim.log_replay import ReplayPlanner

        return ReplayPlanner()
    if kind in ("cnn", "cnn_lstm", "cnn-lstm", "rvsg") and arg:
        from riskmap.planner.bc import BCPlanner

        return BCPlanner.load(arg, expected_kind=kind)
    if kind == "py" and arg:
        factory, kwargs = _from_python(spec, arg, seed)
        return _made(spec, factory, **kwargs)
    factory = _plugin(kind) if arg else None
    if factory is not None:
        return _made(spec, factory, arg, seed=seed)
    raise InputError(f"unknown planner spec {spec!r}; use one of {', '.join(SPECS)}")


def is_planner(obj) -> bool:
    """Whether `obj` keeps the Planner contract's shape: an instance that drives itself, or one
    with callable `reset` and `plan`."""
    if isinstance(obj, type):
        return False
    return bool(getattr(obj, "drives_itself", False)) or all(
        callable(getattr(obj, method, None)) for method in ("reset", "plan"))


def _made(spec: str, factory, *args, **kwargs):
    """`factory(*args, **kwargs)`, checked to be a planner; a factory that fails is one line."""
    try:
        planner = factory(*args, **kwargs)
    except InputError:
        raise
    except Exception as err:  # noqa: BLE001 - a user's factory may raise anything
        raise InputError(f"planner {spec!r} could not be made ({type(err).__name__}: {err}); "
                         "fix its factory or its keys") from None
    if not is_planner(planner):
        raise InputError(f"planner {spec!r} made a {type(planner).__name__}, not a planner; its "
                         "factory must return an object with reset(scene) and plan(scene) -> Plan "
                         "(README, the planner contract)")
    return planner


def _literal(text: str):
    """A `py:` SPEC value: int, finite float, true/false, else the text itself ("nan" stays text)."""
    import math

    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for kind in (int, float):
        try:
            value = kind(text)
        except ValueError:
            continue
        if math.isfinite(value):
            return value
    return text


def _from_python(spec: str, arg: str, seed: int):
    """`py:package.module:Factory?key=value&...` -> (Factory, {key: value, ..., [seed: seed]})."""
    target, _, query = arg.partition("?")
    module_name, _, attribute = target.partition(":")
    if not module_name or not attribute:
        raise InputError(f"planner {spec!r}: write py:package.module:Factory[?key=value&...]")
    kwargs = _spec_keys(spec, query)
    factory = _factory(spec, module_name, attribute)
    _bind_seed(spec, attribute, factory, kwargs, seed)
    return factory, kwargs


def _spec_keys(spec: str, query: str) -> dict:
    """The typed keys of a `py:` SPEC's query (`key=value&...`)."""
    from urllib.parse import parse_qsl

    try:
        pairs = parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query))
    except ValueError:
        raise InputError(f"planner {spec!r}: the part after ? must be key=value pairs joined by &"
                         ) from None
    kwargs = {}
    for key, value in pairs:
        if key in kwargs:
            raise InputError(f"planner {spec!r} gives {key!r} twice; give it once")
        kwargs[key] = _literal(value)
    return kwargs


def _factory(spec: str, module_name: str, attribute: str):
    """The callable `attribute` (dotted) of module `module_name`."""
    import importlib
    import os
    import sys

    if os.getcwd() not in sys.path:
        sys.path.append(os.getcwd())   # as `python -m` would: a module beside the user is found
    try:
        factory = importlib.import_module(module_name)
    except Exception as err:  # noqa: BLE001 - any failure to import is the user's module's
        raise InputError(f"planner {spec!r}: module {module_name!r} cannot be imported "
                         f"({type(err).__name__}: {err}); install it or add it to PYTHONPATH"
                         ) from None
    for part in attribute.split("."):
        factory = getattr(factory, part, None)
        if factory is None:
            raise InputError(f"planner {spec!r}: {module_name} has no {attribute!r}; name a "
                             "factory defined there")
    if not callable(factory):
        raise InputError(f"planner {spec!r}: {attribute} is a {type(factory).__name__}, not a "
                         "factory; name a class or function that returns a planner")
    return factory


def _bind_seed(spec: str, attribute: str, factory, kwargs: dict, seed: int) -> None:
    """Add `seed` to `kwargs` when the factory takes one (and it is not given); refuse keys the
    factory does not take."""
    import inspect

    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):
        return                          # a builtin without a signature: call it and see
    takes_any = any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values())
    if "seed" not in kwargs and (takes_any or "seed" in signature.parameters):
        kwargs["seed"] = seed
    try:
        signature.bind(**kwargs)
    except TypeError as err:
        names = ", ".join(signature.parameters) or "nothing"
        raise InputError(f"planner {spec!r}: {attribute} does not take these keys ({err}); "
                         f"drop them: it takes {names}") from None


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
