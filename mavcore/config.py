"""Strict construction of frozen dataclasses from YAML/JSON dictionaries.

``from_dict(cls, data, source)`` walks the dataclass's type hints and
rejects unknown keys, missing required keys and wrong types, naming the
file and the dotted key path (STYLE.md rule 5). Supported field types:
``float``, ``int``, ``bool``, ``str``, nested dataclasses, ``Optional[...]``
(``X | None``), ``tuple[X, ...]``, ``tuple[X, Y, Z]``, ``Literal[...]`` and
unions of those (tried in order).
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from typing import Any, Literal, Union

from .errors import MissionError
from .inputs import brief

_NONE = type(None)
_YAML11_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")


def _kind(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return f"a boolean ({value})"
    if isinstance(value, (int, float)):
        return f"a number ({brief(value)})"
    if isinstance(value, str):
        return f"a string ({brief(value)})"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


def _convert(tp: Any, value: Any, source: str, key: str, error: type[Exception]) -> Any:
    where = f"{source}: key '{key}'" if key else source
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)

    if tp is Any:
        return value
    if origin in (Union, types.UnionType):
        if value is None and _NONE in args:
            return None
        last: Exception | None = None
        for arg in args:
            if arg is _NONE:
                continue
            try:
                return _convert(arg, value, source, key, error)
            except error as exc:  # try the next member of the union
                last = exc
        assert last is not None
        raise last
    if origin is Literal:
        if value in args:
            return value
        raise error(where, f"expected one of {', '.join(repr(a) for a in args)}, got {_kind(value)}")
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise error(where, f"expected a list, got {_kind(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, source, f"{key}[{i}]", error) for i, v in enumerate(value))
        if len(value) != len(args):
            raise error(where, f"expected a list of {len(args)} items, got {len(value)}")
        return tuple(_convert(a, v, source, f"{key}[{i}]", error) for i, (a, v) in enumerate(zip(args, value)))
    if dataclasses.is_dataclass(tp):
        return from_dict(tp, value, source, key, error)
    if tp is float:
        if isinstance(value, str) and _YAML11_FLOAT.fullmatch(value.strip()):
            # YAML 1.1 (PyYAML) reads 5e-4 and 1e3 as strings: it wants a
            # dot and a signed exponent (5.0e-4). Accept what is plainly a number.
            value = float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise error(where, f"expected a number, got {_kind(value)}")
        if not math.isfinite(value):
            raise error(where, f"expected a finite number, got {value}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                return int(value)
            raise error(where, f"expected an integer, got {_kind(value)}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise error(where, f"expected true or false, got {_kind(value)}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise error(where, f"expected a string, got {_kind(value)}")
        return value
    raise TypeError(f"unsupported field type {tp!r}")  # programming error, not input


def from_dict(cls: type, data: Any, source: str, prefix: str = "", error: type[Exception] = MissionError):
    """Build the frozen dataclass ``cls`` from ``data``.

    Parameters
    ----------
    cls : dataclass type
        Target; field defaults make keys optional.
    data : mapping
        Parsed YAML/JSON.
    source : str
        File name used in error messages.
    prefix : str
        Dotted key path of ``data`` inside the file (for nested sections).
    error : exception type
        ``InputError`` subclass raised on bad input.

    Raises
    ------
    error
        On unknown keys, missing required keys, wrong types, or a
        ``__post_init__`` validation failure (ValueError with a message).
    """
    where = f"{source}: key '{prefix}'" if prefix else source
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise error(where, f"expected a mapping, got {_kind(data)}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    for k in data:
        if k not in fields:
            raise error(f"{source}: key '{prefix + '.' if prefix else ''}{brief(k, 40).strip(chr(39))}'",
                        f"unknown key (known: {', '.join(sorted(fields))})")
    kwargs = {}
    for name, f in fields.items():
        key = f"{prefix}.{name}" if prefix else name
        if name in data:
            kwargs[name] = _convert(hints[name], data[name], source, key, error)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise error(f"{source}: key '{key}'", "missing")
    try:
        return cls(**kwargs)
    except ValueError as exc:
        if isinstance(exc, error):
            raise
        raise error(where, str(exc)) from None


def to_dict(obj: Any) -> Any:
    """Dataclass (possibly nested) -> plain dict/list structure for JSON/YAML."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_dict(v) for v in obj]
    return obj
