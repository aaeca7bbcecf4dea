"""Strict conversion of TOML tables into frozen dataclasses.

Every key must be a field, every value must have the field's type; anything else is an
:class:`~autonomy.common.errors.InputError` whose one line names the file, the dotted key and
what was expected. ``--set key.sub=value`` overrides go through the same checks.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from typing import Any

from autonomy.common.errors import InputError


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    if dataclasses.is_dataclass(tp):
        return "a table"
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"an array of {_type_name(args[0]).removeprefix('a ').removeprefix('an ')}s"
        return f"an array of {len(args)} values"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(tp))
    return str(tp)


def _describe(value: Any) -> str:
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, str):
        return f"string {value!r}"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "an array"
    return f"{type(value).__name__} {value!r}"


def convert(tp: Any, value: Any, key: str, source: str) -> Any:
    """Convert one TOML value to ``tp`` or raise InputError naming ``source`` and ``key``."""

    def fail() -> typing.NoReturn:
        raise InputError(f"{source}: key '{key}' expected {_type_name(tp)}, got {_describe(value)}")

    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            fail()
        return from_dict(tp, value, source=source, prefix=key)
    if tp is bool:
        if not isinstance(value, bool):
            fail()
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            fail()
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            fail()
        if not math.isfinite(value):
            raise InputError(f"{source}: key '{key}' expected a finite number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            fail()
        return value
    if origin is tuple:
        if not isinstance(value, list):
            fail()
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(args[0], v, f"{key}[{i}]", source) for i, v in enumerate(value))
        if len(value) != len(args):
            fail()
        return tuple(convert(a, v, f"{key}[{i}]", source) for i, (a, v) in enumerate(zip(args, value, strict=True)))
    if origin in (typing.Union, types.UnionType):
        for a in typing.get_args(tp):
            try:
                return convert(a, value, key, source)
            except InputError:
                continue
        fail()
    raise TypeError(f"unsupported field type {tp!r} for {key}")  # a bug, not user input


def from_dict(cls: type, data: dict, *, source: str, prefix: str = "") -> Any:
    """Build dataclass ``cls`` from a dict, strictly (unknown keys and wrong types are errors)."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    kwargs = {}
    for k, v in data.items():
        key = f"{prefix}.{k}" if prefix else k
        if k not in fields:
            expected = ", ".join(sorted(fields))
            raise InputError(f"{source}: unknown key '{key}' (expected one of: {expected})")
        kwargs[k] = convert(hints[k], v, key, source)
    for name, f in fields.items():
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING and name not in kwargs:
            key = f"{prefix}.{name}" if prefix else name
            raise InputError(f"{source}: missing key '{key}' ({_type_name(hints[name])})")
    try:
        return cls(**kwargs)
    except InputError as exc:
        msg = str(exc)
        raise InputError(msg if msg.startswith(source) else f"{source}: {msg}") from None


def read_toml(path: Any) -> dict:
    """A TOML file as a dict, or an InputError naming the file (missing, invalid, not UTF-8)."""
    from pathlib import Path

    path, src = Path(path), str(path)
    if path.is_dir():
        raise InputError(f"{src}: a directory; expected a scenario file (*.toml)")
    if not path.is_file():
        raise InputError(f"{src}: scenario file not found")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{src}: invalid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{src}: not a UTF-8 text file") from None


def to_dict(obj: Any) -> Any:
    """A dataclass tree as plain TOML/JSON-able values (tuples become lists)."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (tuple, list)):
        return [to_dict(v) for v in obj]
    return obj


def parse_override(text: str) -> tuple[list[str], Any]:
    """Parse ``a.b.c=VALUE`` (VALUE in TOML syntax; bare words are taken as strings)."""
    if "=" not in text:
        raise InputError(f"--set {text!r}: expected KEY=VALUE, e.g. robot.max_speed_mps=0.5")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise InputError(f"--set {text!r}: expected a dotted key before '='")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return key.split("."), value


def apply_overrides(data: dict, overrides: list[str]) -> dict:
    """Set each ``--set`` override into a nested dict (a deep copy is returned)."""
    import copy

    out = copy.deepcopy(data)
    for text in overrides:
        path, value = parse_override(text)
        node = out
        for part in path[:-1]:
            nxt = node.setdefault(part, {})
            if not isinstance(nxt, dict):
                raise InputError(f"--set {text!r}: '{part}' is not a table")
            node = nxt
        node[path[-1]] = value
    return out


def _toml_value(v: Any, key: str) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        import json

        return json.dumps(v, ensure_ascii=False)  # a JSON string is a TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x, key) for x in v) + "]"
    raise TypeError(f"{key}: no TOML form for {type(v).__name__}")  # a bug, not user input


def _is_table_array(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and bool(v) and all(isinstance(x, dict) for x in v)


def to_toml(data: dict, prefix: str = "") -> str:
    """A nested dict of TOML values (``to_dict``'s output) as TOML text: plain keys first,
    then sub-tables and arrays of tables. Values a scenario file cannot hold are left
    out, and loading the text fills their defaults back in: None (TOML has no null) and
    non-finite numbers (the loader takes finite ones; a NaN default means "not set")."""
    lines: list[str] = []
    later: list[str] = []
    for k, v in data.items():
        path = f"{prefix}.{k}" if prefix else k
        if v is None or isinstance(v, float) and not math.isfinite(v):
            continue
        if isinstance(v, dict):
            body = to_toml(v, path)
            later.append(f"\n[{path}]\n{body}" if not body.startswith("\n[") else f"\n[{path}]{body}")
        elif _is_table_array(v):
            for item in v:
                body = to_toml(item, path)
                later.append(f"\n[[{path}]]\n{body}" if not body.startswith("\n[") else f"\n[[{path}]]{body}")
        else:
            lines.append(f"{k} = {_toml_value(v, path)}")
    head = "\n".join(lines) + ("\n" if lines else "")
    return head + "".join(later)


def parse_floats(text: str, option: str, count: int, names: str, example: str) -> tuple[float, ...]:
    """A command-line list of ``count`` finite numbers separated by commas; otherwise one
    InputError naming ``option``, what it expects (``names``) and an ``example``."""
    try:
        vals = tuple(float(p) for p in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != count or not all(math.isfinite(v) for v in vals):
        raise InputError(f"{option} {text!r}: expected {names}, e.g. {example}")
    return vals
