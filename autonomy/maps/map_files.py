"""What reading the map files needs, shared by the vector map (:mod:`autonomy.maps.vectormap`)
and the navigation graph (:mod:`autonomy.maps.navgraph`): the error that names the file,
the line and what was expected; a file read as UTF-8 text with a one-line error for each
way that fails; and the JSON checker (:class:`_JsonCtx`) that finds the line of a
malformed element only when it reports one (a well-formed file is read without that
search).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from autonomy.common.errors import InputError

PathLike = str | os.PathLike[str]


class MapFormatError(InputError):
    """A malformed map or graph file; ``str(err)`` names the file, the line and what was expected."""

    def __init__(self, message: str, *, source: str | None = None, line: int | None = None):
        super().__init__(message)
        self.source = source
        """The file name (or ``"<string>"``) the error is in."""
        self.line = line
        """1-based line number, when known."""


def _fail(source: str, line: int | None, msg: str, col: int | None = None) -> MapFormatError:
    where = source if line is None else (f"{source}:{line}" if col is None else f"{source}:{line}:{col}")
    return MapFormatError(f"{where}: {msg}", source=source, line=line)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _short(s: str, n: int = 40) -> str:
    r = repr(s)
    return r if len(r) <= n else r[: n - 4] + "...'"


# --------------------------------------------------------------------------- JSON helpers

_JSON_WS = " \t\n\r"


def _skip_ws(text: str, i: int) -> int:
    n = len(text)
    while i < n and text[i] in _JSON_WS:
        i += 1
    return i


def _json_offset(text: str, path: Sequence[int | str]) -> int | None:
    """Character offset where the JSON value at ``path`` starts, or None if not found."""
    dec = json.JSONDecoder()
    try:
        i = _skip_ws(text, 0)
        for comp in path:
            if isinstance(comp, int):
                if text[i] != "[":
                    return None
                i = _skip_ws(text, i + 1)
                for _ in range(comp):
                    _, i = dec.raw_decode(text, i)
                    i = _skip_ws(text, i)
                    if text[i] != ",":
                        return None
                    i = _skip_ws(text, i + 1)
            else:
                if text[i] != "{":
                    return None
                i = _skip_ws(text, i + 1)
                while True:
                    key, i = dec.raw_decode(text, i)
                    i = _skip_ws(text, i)
                    if text[i] != ":":
                        return None
                    i = _skip_ws(text, i + 1)
                    if key == comp:
                        break
                    _, i = dec.raw_decode(text, i)
                    i = _skip_ws(text, i)
                    if text[i] != ",":
                        return None
                    i = _skip_ws(text, i + 1)
        return i
    except (ValueError, IndexError):
        return None


def _json_line(text: str, path: Sequence[int | str]) -> int | None:
    off = _json_offset(text, path)
    return None if off is None else text.count("\n", 0, off) + 1


def _path_str(path: Sequence[int | str]) -> str:
    out = ""
    for c in path:
        out += f"[{c}]" if isinstance(c, int) else (f".{c}" if out else c)
    return out or "top level"


def _json_type(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, int | float):
        return f"the number {v!r}"
    if isinstance(v, str):
        return f"the string {_short(v)}"
    if isinstance(v, list):
        return "an array"
    if isinstance(v, dict):
        return "an object"
    return type(v).__name__


class _JsonCtx:
    """Raises MapFormatError for a JSON document, finding element line numbers lazily."""

    def __init__(self, text: str, source: str):
        self.text = text
        self.source = source

    def fail(self, path: Sequence[int | str], msg: str) -> MapFormatError:
        line = _json_line(self.text, path)
        return _fail(self.source, line, f"{_path_str(path)}: {msg}")

    def obj(self, v: Any, path: Sequence[int | str], what: str) -> dict[str, Any]:
        if not isinstance(v, dict):
            raise self.fail(path, f"expected {what}, got {_json_type(v)}")
        return v

    def key(self, d: dict[str, Any], k: str, path: Sequence[int | str]) -> Any:
        if k not in d:
            raise self.fail(path, f'missing key "{k}"')
        return d[k]

    def number(self, v: Any, path: Sequence[int | str]) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(path, f"expected a number, got {_json_type(v)}")
        try:
            f = float(v)
        except OverflowError:
            f = math.inf
        if not math.isfinite(f):
            raise self.fail(path, f"expected a finite number, got {_short(str(v))}")
        return f

    def integer(self, v: Any, path: Sequence[int | str]) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(path, f"expected an integer, got {_json_type(v)}")
        return int(v)

    def boolean(self, v: Any, path: Sequence[int | str]) -> bool:
        if not isinstance(v, bool):
            raise self.fail(path, f"expected true or false, got {_json_type(v)}")
        return v


def _json_load(text: str, source: str) -> Any:
    if text.startswith("\ufeff"):
        text = text[1:]
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise _fail(source, e.lineno, f"invalid JSON: {e.msg}", col=e.colno) from None
    except RecursionError:
        raise _fail(source, None, "invalid JSON: nested too deeply") from None


def _read_text(path: PathLike) -> tuple[str, str]:
    source = os.fspath(path)
    try:
        with open(source, encoding="utf-8") as f:
            return f.read(), source
    except FileNotFoundError:
        raise _fail(source, None, "file not found") from None
    except IsADirectoryError:
        raise _fail(source, None, "is a directory, expected a map file") from None
    except PermissionError:
        raise _fail(source, None, "permission denied") from None
    except UnicodeDecodeError as e:
        raise _fail(source, None, f"not UTF-8 text ({e.reason} at byte {e.start})") from None
