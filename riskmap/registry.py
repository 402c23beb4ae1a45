"""One parser for planner SPEC strings (DESIGN §2).

Built in:

    idm              the IDM/MOBIL "human": the ego drives itself, no plan is made
    yielding         IDM/MOBIL that gives way at conflict zones by gap acceptance (the
                     intersection teacher, `riskmap.sim.drivers.yielding`)
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
    cr:package.module:Factory[?predict=none|cv|toolkit&key=value&...]
                     a CommonRoad planner (`plan(sc, pp, ref_path=None) -> Trajectory`,
                     commonroad-io's `TrajectoryPlannerInterface`): `Factory(key=value, ...,
                     seed=SEED)` as for `py:`, wrapped in
                     `riskmap.planner.commonroad_planner.CommonRoadPlanner` with the obstacles'
                     prediction `predict` (default cv), which is not passed to the factory
    NAME:ARG         entry `NAME` of the entry-point group `riskmap.planners` (an installed
                     package declares it), called as `factory(ARG, seed=SEED)`

A `py:` or `cr:` SPEC may carry `name=NAME` among its keys: the planner's display name in tables, figure
titles and summaries (letters, digits and `. _ + -`); it is not passed to the factory. Without
one, a planner is shown by a short name made from its SPEC (`display_name`): `idm`, `cv`, ... as
written, a checkpoint's file stem for `riskmap:`/`cnn:`/`cnn_lstm:`/`rvsg:`, the factory's name for
`py:` and `cr:`, `NAME-<ARG's short name>` for a plug-in (`guard-riskmap_highway`); two planners of one run
that would share a name are told apart by `-2`, `-3`, ... (`display_names`). Records keep the
whole SPEC beside the name.

Either must return a planner (`riskmap.sim.loop.plan.Planner`: `reset(scene)`, `plan(scene) -> Plan`,
or `drives_itself = True`); anything else is a one-line error naming the SPEC. The guard is an
entry-point plug-in (`guard`, `guarded`, `guard-always`, declared in pyproject.toml): it wraps a
planner made by this registry, so it sits above it and the registry never imports it.
"""

from __future__ import annotations

from rasterize.errors import InputError
from riskmap.sim.loop.plan import HumanDriver, traits_of

PLUGIN_GROUP = "riskmap.planners"
SPECS = ("idm", "yielding", "cv", "replay", "riskmap:PATH", "cnn:PATH", "cnn_lstm:PATH", "rvsg:PATH",
         "guard:SPEC", "guard-always:SPEC", "py:module:Factory[?key=value&...]",
         "cr:module:Factory[?predict=none|cv|toolkit&key=value&...]")
# The one help text of every command-line flag that takes a planner SPEC.
SPEC_HELP = ("planner SPEC: idm, yielding, cv, replay (recordings), riskmap:PATH, cnn:PATH, "
             "cnn_lstm:PATH, rvsg:PATH, guard:SPEC, your own py:package.module:Factory[?key=value&...], "
             "a CommonRoad planner cr:package.module:Factory[?predict=none|cv|toolkit&key=value&...] "
             "(the key name=NAME sets its name in tables and figures) or an installed plug-in NAME:ARG "
             "(docs/guide/your-own-planner.md)")
# A display name goes into tables, figure titles and file names: one path component, no spaces.
NAME_PATTERN = r"[A-Za-z0-9][A-Za-z0-9._+-]{0,63}"
NAME_KEY = "name"
_CHECKPOINT_KINDS = ("riskmap", "cnn", "cnn_lstm", "cnn-lstm", "rvsg")
_SIMPLE_KINDS = ("idm", "yielding", "cv", "replay")
_KEYED_KINDS = ("py:", "cr:")         # SPECs with ?key=value&... (and so a name= key)
PREDICT_KEY = "predict"               # cr: the obstacles' prediction, the adapter's, not the factory's


def make_planner(spec: str, seed: int = 0, goal_variance: float | None = None):
    """A `Planner` (or `HumanDriver`) for `spec`; `goal_variance` (cells²) overrides a risk-map
    checkpoint's planning-time goal variance."""
    spec, _ = split_name(spec)          # the name is the toolkit's, never a factory's key
    kind, _, arg = spec.partition(":")
    if kind == "idm" and not arg:
        return HumanDriver()
    if kind == "yielding" and not arg:
        from riskmap.sim.drivers.yielding import demonstrator

        return demonstrator("yielding")
    if kind == "cv" and not arg:
        from riskmap.planner.baselines import ConstantVelocityPlanner

        return ConstantVelocityPlanner()
    if kind == "riskmap" and arg:
        from riskmap.planner.riskmap_planner import load_planner

        return load_planner(arg, seed=seed, goal_variance=goal_variance)
    if kind == "replay" and not arg:
        from riskmap.sim.worlds.log_replay import ReplayPlanner

        return ReplayPlanner()
    if kind in ("cnn", "cnn_lstm", "cnn-lstm", "rvsg") and arg:
        from riskmap.planner.bc import BCPlanner

        return BCPlanner.load(arg, expected_kind=kind)
    if kind == "py" and arg:
        factory, kwargs = _from_python(spec, arg, seed)
        return _made(spec, factory, **kwargs)
    if kind == "cr" and arg:
        return _commonroad_planner(spec, arg, seed)
    factory = _plugin(kind) if arg else None
    if factory is not None:
        return _made(spec, factory, arg, seed=seed)
    raise InputError(f"unknown planner spec {spec!r}; use one of {', '.join(SPECS)}")


def split_name(spec: str) -> tuple[str, str | None]:
    """(`spec` without its `name=` key, that name or None). Only `py:` SPECs have keys; the
    others are returned whole (a plug-in's ARG, e.g. `guard:py:...?name=x`, is split when the
    plug-in makes its inner planner)."""
    from urllib.parse import unquote_plus

    target, sep, query = spec.partition("?")
    if not spec.startswith(_KEYED_KINDS) or not sep:
        return spec, None
    items = query.split("&")
    named = [item for item in items if unquote_plus(item.partition("=")[0]) == NAME_KEY]
    if not named:
        return spec, None
    if len(named) > 1:
        raise InputError(f"planner {spec!r} gives {NAME_KEY!r} twice; give it once")
    name = unquote_plus(named[0].partition("=")[2])
    _check_name(spec, name)
    rest = [item for item in items if item not in named]
    return target + ("?" + "&".join(rest) if rest else ""), name


def _check_name(spec: str, name: str) -> None:
    import re

    if not re.fullmatch(NAME_PATTERN, name):
        raise InputError(f"planner {spec!r}: name={name!r} cannot name a planner in tables and file "
                         "names; use 1 to 64 letters, digits, '.', '_', '+' or '-', starting with a "
                         "letter or digit")


def display_name(spec: str) -> str:
    """The planner's name in tables and figure titles: its `name=` key, else a short name made
    from the SPEC (module docstring). Reads the SPEC only: nothing is imported or loaded."""
    bare, name = split_name(spec)
    return name if name is not None else _default_name(bare)


def _default_name(spec: str) -> str:
    import re
    from pathlib import PurePath

    kind, sep, arg = spec.partition(":")
    if not sep:
        text = kind
    elif kind in _CHECKPOINT_KINDS:
        text = PurePath(arg).name.removesuffix(".safetensors")
    elif kind in ("py", "cr"):
        # the factory, dotted attributes and keys dropped: `...:GapKeeper?headway_s=2` -> GapKeeper
        text = arg.partition("?")[0].rpartition(":")[2].rpartition(".")[2]
    else:                               # a plug-in NAME:ARG; its ARG may itself be a SPEC
        text = f"{kind}-{_short_arg(arg)}"
    # text from a SPEC may hold ':', '/', '?' ...; a name must be one clean file-name component
    text = re.sub(r"[^A-Za-z0-9._+-]+", "-", text).strip("-._+")[:64].rstrip("-._+")
    return text or "planner"


def _short_arg(arg: str) -> str:
    """A plug-in ARG's short name: a SPEC's display name, else its last path component."""
    from pathlib import PurePath

    kind, sep, _ = arg.partition(":")
    if kind in _SIMPLE_KINDS + _CHECKPOINT_KINDS + ("py", "cr") or (sep and kind in _plugin_names()):
        return display_name(arg)
    return PurePath(arg).name.removesuffix(".safetensors") if arg else ""


def _plugin_names() -> set[str]:
    from importlib.metadata import entry_points

    return {entry.name for entry in entry_points(group=PLUGIN_GROUP)}


def display_names(specs) -> dict[str, str]:
    """SPEC -> display name for the planners of one run, each name used once. A `name=` given
    is kept as written (two planners given the same one is an error); a default name that is
    taken gets `-2`, `-3`, ... in the order the SPECs come."""
    specs = list(dict.fromkeys(specs))
    given = {spec: split_name(spec)[1] for spec in specs}
    taken: dict[str, str] = {}
    for spec, name in given.items():
        if name is not None and name in taken:
            raise InputError(f"planners {taken[name]!r} and {spec!r} are both named {name!r}; give "
                             "each its own name=")
        if name is not None:
            taken[name] = spec
    names = {}
    for spec in specs:
        names[spec] = given[spec] if given[spec] is not None else _unique(_default_name(spec), taken)
        taken.setdefault(names[spec], spec)
    return names


def _unique(name: str, taken: dict) -> str:
    if name not in taken:
        return name
    number = 2
    while f"{name}-{number}" in taken:
        number += 1
    return f"{name}-{number}"


def is_planner(obj) -> bool:
    """Whether `obj` keeps the Planner contract's shape: an instance that drives itself, or one
    with callable `reset` and `plan`."""
    if isinstance(obj, type):
        return False
    return bool(traits_of(obj).drives_itself) or all(
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
                         "(docs/guide/your-own-planner.md, \"The planner contract\")")
    return planner


def _commonroad_planner(spec: str, arg: str, seed: int):
    """`cr:package.module:Factory?predict=...&key=value&...`: the factory's planner, checked to
    have `plan(sc, pp, ref_path)`, wrapped in `CommonRoadPlanner` (one line for what is wrong)."""
    from riskmap.planner.commonroad_planner import PREDICTIONS, CommonRoadPlanner

    target, _, query = arg.partition("?")
    keys = _spec_keys(spec, query)
    predict = keys.pop(PREDICT_KEY, "cv")
    if predict not in PREDICTIONS:
        raise InputError(f"planner {spec!r}: predict={predict!r}; use one of {', '.join(PREDICTIONS)}")
    rest = "&".join(f"{k}={v}" for k, v in _raw_pairs(query) if k != PREDICT_KEY)
    factory, kwargs = _from_python(spec, target + ("?" + rest if rest else ""), seed)
    try:
        inner = factory(**kwargs)
    except InputError:
        raise
    except Exception as err:  # noqa: BLE001 - a user's factory may raise anything
        raise InputError(f"planner {spec!r} could not be made ({type(err).__name__}: {err}); "
                         "fix its factory or its keys") from None
    if isinstance(inner, type) or not callable(getattr(inner, "plan", None)):
        raise InputError(f"planner {spec!r} made a {type(inner).__name__}, which has no "
                         "plan(sc, pp, ref_path=None) -> Trajectory; a cr: factory must return a "
                         "CommonRoad planner (commonroad.planning.planner_interface."
                         "TrajectoryPlannerInterface)")
    return CommonRoadPlanner(inner, predict=predict)


def _raw_pairs(query: str) -> list[tuple[str, str]]:
    """The raw (key, value) pairs of a SPEC's query, URL-quoted as written."""
    return [(item.partition("=")[0], item.partition("=")[2]) for item in query.split("&") if item]


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
    key = (split_name(spec)[0], seed, goal_variance)     # one planner, however it is named
    if key not in _CACHED:
        _CACHED[key] = make_planner(spec, seed=seed, goal_variance=goal_variance)
    return _CACHED[key]
