"""Turning plain YAML/JSON values into frozen config dataclasses, with one-line InputErrors.

Every config of the `adversary` package is a frozen dataclass whose fields are plain scalars
(bool, int, float, str), tuples of them, or nested config dataclasses. `from_mapping` checks
unknown keys, missing required keys and scalar types, naming the offending input (`where`).
"""

from __future__ import annotations

import dataclasses
import math
import typing
from typing import Any

from rasterize.errors import InputError

_SCALARS = {"bool": bool, "int": int, "float": float, "str": str}


def _scalar(value: Any, type_name: str, where: str):
    """Coerce `value` to the scalar type named `type_name` (int is accepted for float)."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if type_name == "bool" and isinstance(value, bool):
        return value
    if type_name == "int" and number and isinstance(value, int):
        return value
    if type_name == "float" and number and math.isfinite(value):
        return float(value)
    if type_name == "str" and isinstance(value, str) and value:
        return value
    kind = {"str": "a non-empty string", "int": "an int"}.get(type_name, f"a {type_name}")
    shown = repr(value) if len(repr(value)) <= 80 else repr(value)[:77] + "..."
    raise InputError(f"{where}: expected {kind[kind.index(' ') + 1:] if type_name != 'str' else kind}, "
                     f"got {shown}; change it to {kind}")


def from_mapping(cls, data: Any, where: str):
    """An instance of the frozen dataclass `cls` built from the mapping `data`."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        shown = repr(data) if len(repr(data)) <= 80 else repr(data)[:77] + "..."
        raise InputError(f"{where}: expected a mapping of {cls.__name__} fields (key: value lines), "
                         f"got {shown}; write one key per line")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r}; remove it or use one of the allowed "
                         f"keys: {', '.join(fields)}")
    values = {}
    for name, f in fields.items():
        key_where = f"{where}.{name}"
        if name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise InputError(f"{where}: missing required key {name!r}; add it")
            continue
        values[name] = _convert(data[name], hints[name], key_where)
    return cls(**values)


def _convert(value: Any, hint, where: str):
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if dataclasses.is_dataclass(hint):
        return from_mapping(hint, value, where)
    if origin is typing.Union or str(origin) == "<class 'types.UnionType'>":
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _convert(value, inner[0], where)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise InputError(f"{where}: expected a list, got {value!r}")
        item = args[0]
        return tuple(_convert(v, item, f"{where}[{i}]") for i, v in enumerate(value))
    if hint is dict or origin is dict:
        if not isinstance(value, dict):
            raise InputError(f"{where}: expected a mapping, got {value!r}")
        return dict(value)
    if getattr(hint, "__name__", None) in _SCALARS:
        return _scalar(value, hint.__name__, where)
    raise TypeError(f"config field type {hint!r} is not supported")  # a programming error


def to_plain(obj) -> Any:
    """A frozen config dataclass as plain JSON-ready values (tuples become lists)."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (tuple, list)):
        return [to_plain(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_plain(v) for k, v in obj.items()}
    return obj


def require(condition: bool, message: str) -> None:
    """Raise an InputError with `message` unless `condition` holds."""
    if not condition:
        raise InputError(message)
