"""Vector maps (walls as 2D line segments) and navigation graphs, with their file formats.

Formats (CoBot / UT AMRL, docs/architecture.md):

- Text vector map (``*.vectormap.txt``, ``*_vector.txt``, any ``.txt``): one wall per
  line, ``x1, y1, x2, y2`` in metres. Commas with optional spaces, or plain whitespace.
  Blank lines and lines starting with ``#`` are skipped.
- JSON vector map (``*.vectormap.json``, any ``.json``):
  ``[{"p0": {"x": .., "y": ..}, "p1": {"x": .., "y": ..}}, ...]``.
- Navigation graph (``*.navigation.json``): ``{"nodes": [{"id", "loc": {"x", "y"}}],
  "edges": [{"s0_id", "s1_id", "has_door", "has_stairs", "has_elevator",
  "has_automated_door", "max_speed", "max_clearance"}]}``.

Every malformed input raises :class:`MapFormatError`, whose one-line message names the
file, the line (and for JSON the element path, e.g. ``[3].p1.y``) and what was expected.

Loading also checks the walls (:mod:`autonomy.maps.map_hygiene`): zero-length and duplicate
segments are dropped, overlapping collinear ones reported, and a map whose extent is not a
building in metres (a millimetre map, say) refused. Each finding is one warning line on the
``"depthnav.map"`` logger; ``load_vectormap(path, scale=0.001)`` reads a millimetre map.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.map_hygiene import Finding, clean_segments, log_findings

__all__ = [
    "MapFormatError",
    "VectorMap",
    "NavNode",
    "NavEdge",
    "NavGraph",
    "parse_vectormap_text",
    "parse_vectormap_json",
    "format_vectormap_text",
    "format_vectormap_json",
    "load_vectormap",
    "load_vectormap_checked",
    "save_vectormap",
    "check_vectormap",
    "parse_navgraph_json",
    "format_navgraph_json",
    "load_navgraph",
    "save_navgraph",
    "TEXT_SUFFIXES",
    "JSON_SUFFIXES",
]

#: File suffixes read as text vector maps / JSON vector maps.
TEXT_SUFFIXES = (".txt",)
JSON_SUFFIXES = (".json",)

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


# --------------------------------------------------------------------------- VectorMap


@dataclass(frozen=True, eq=False)
class VectorMap:
    """Walls of a floor as N line segments ``x1, y1, x2, y2`` in metres (world frame).

    The array is stored as a read-only, C-contiguous float64 copy. Segments must be finite
    and of non-zero length (loading a file drops zero-length ones and says so).
    """

    segments: np.ndarray
    """(N, 4) float64: ``x1, y1, x2, y2`` of each wall in metres."""
    name: str = ""
    """Human-readable map name (file stem when loaded)."""

    def __post_init__(self) -> None:
        try:
            seg = np.array(self.segments, dtype=np.float64, order="C", copy=True)
        except (TypeError, ValueError) as e:
            raise InputError(f"vector map {self.name!r}: segments are not numeric ({e})") from None
        if seg.ndim == 2 and seg.shape[0] == 0:
            seg = seg.reshape(0, 4)
        elif seg.ndim == 1 and seg.size == 0:
            seg = seg.reshape(0, 4)
        if seg.ndim != 2 or seg.shape[1] != 4:
            raise InputError(
                f"vector map {self.name!r}: segments must have shape (N, 4) [x1, y1, x2, y2], got {seg.shape}"
            )
        finite = np.isfinite(seg).all(axis=1)
        if not finite.all():
            i = int(np.flatnonzero(~finite)[0])
            raise InputError(f"vector map {self.name!r}: segment {i} is not finite: {seg[i].tolist()}")
        zero = (seg[:, 0] == seg[:, 2]) & (seg[:, 1] == seg[:, 3])
        if zero.any():
            i = int(np.flatnonzero(zero)[0])
            raise InputError(f"vector map {self.name!r}: segment {i} has zero length: {seg[i].tolist()}")
        object.__setattr__(self, "segments", _readonly(seg))
        object.__setattr__(self, "name", str(self.name))

    @classmethod
    def from_segments(cls, segments: Any, name: str = "") -> VectorMap:
        """Build from anything array-like of shape (N, 4); validates shape and finiteness."""
        return cls(segments=segments, name=name)

    @property
    def n_segments(self) -> int:
        """Number of wall segments N."""
        return int(self.segments.shape[0])

    @property
    def p0(self) -> np.ndarray:
        """(N, 2) start points."""
        return self.segments[:, 0:2]

    @property
    def p1(self) -> np.ndarray:
        """(N, 2) end points."""
        return self.segments[:, 2:4]

    @property
    def lengths(self) -> np.ndarray:
        """(N,) segment lengths in metres."""
        s = self.segments
        return np.hypot(s[:, 2] - s[:, 0], s[:, 3] - s[:, 1])

    @property
    def total_length_m(self) -> float:
        """Summed wall length in metres."""
        return float(self.lengths.sum())

    @property
    def normals(self) -> np.ndarray:
        """(N, 2) unit left normals of each segment's direction p0 -> p1."""
        s = self.segments
        d = s[:, 2:4] - s[:, 0:2]
        n = np.stack([-d[:, 1], d[:, 0]], axis=1)
        return n / np.hypot(n[:, 0], n[:, 1])[:, None]

    def extent(self) -> tuple[float, float, float, float]:
        """Bounding box ``(xmin, ymin, xmax, ymax)`` of all walls."""
        if self.n_segments == 0:
            raise InputError(f"vector map {self.name!r} has no segments, so no extent")
        s = self.segments
        xs = s[:, 0::2]
        ys = s[:, 1::2]
        return (float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max()))

    def scaled(self, factor: float) -> VectorMap:
        """The same walls with every coordinate times ``factor`` (0.001 for a millimetre map)."""
        _check_scale(factor)
        return VectorMap(self.segments * float(factor), name=self.name)

    def __repr__(self) -> str:
        return f"VectorMap(name={self.name!r}, n_segments={self.n_segments})"


def _check_scale(factor: Any) -> None:
    if isinstance(factor, bool) or not (isinstance(factor, int | float) and math.isfinite(factor) and factor > 0):
        raise InputError(f"scale: expected a positive number (0.001 for a map in millimetres), got {factor!r}")


# --------------------------------------------------------------------------- text format

_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_WS_CHARS = " \t\r\f\v"
_SP = r"[ \t\r\f\v]"
_COMMA_LINE = re.compile(
    rf"({_NUM}){_SP}*,{_SP}*({_NUM}){_SP}*,{_SP}*({_NUM}){_SP}*,{_SP}*({_NUM})", re.ASCII
)
_SPACE_LINE = re.compile(rf"({_NUM}){_SP}+({_NUM}){_SP}+({_NUM}){_SP}+({_NUM})", re.ASCII)
_NUM_RE = re.compile(_NUM, re.ASCII)
_FIELDS = '"x1, y1, x2, y2"'


def _short(s: str, n: int = 40) -> str:
    r = repr(s)
    return r if len(r) <= n else r[: n - 4] + "...'"


def _diagnose_text_line(s: str, lineno: int, source: str) -> MapFormatError:
    """Explain why a (stripped, non-comment) line is not four numbers."""
    if "," in s:
        fields = [f.strip(_WS_CHARS) for f in s.split(",")]
    else:
        fields = [f for f in re.split(f"{_SP}+", s) if f]
    if len(fields) != 4:
        return _fail(source, lineno, f"expected 4 numbers {_FIELDS}, got {len(fields)} fields")
    names = ("x1", "y1", "x2", "y2")
    for name, f in zip(names, fields, strict=True):
        if _NUM_RE.fullmatch(f):
            continue
        if f == "":
            return _fail(source, lineno, f"expected a number for {name}, got an empty field")
        try:
            v = float(f)
        except ValueError:
            v = None
        if v is not None and not math.isfinite(v):
            return _fail(source, lineno, f"expected a finite number for {name}, got {_short(f)}")
        return _fail(source, lineno, f"expected a number for {name}, got {_short(f)}")
    return _fail(source, lineno, f"expected 4 numbers {_FIELDS}, could not parse {_short(s)}")


def _finish(
    arr: np.ndarray, labels: Any, source: str, unit: str, scale: float, checks: bool
) -> tuple[VectorMap, list[Finding]]:
    """Scale and check parsed segments; raise the first error, return the map and the rest."""
    _check_scale(scale)
    if scale != 1:
        arr = arr * float(scale)
    res = clean_segments(arr, source, labels, unit, checks=checks)
    for f in res.findings:
        if f.severity == "error":
            log_findings(res.warnings)
            raise MapFormatError(f.message, source=source, line=f.line)
    return VectorMap(res.segments, name=_stem_name(source)), list(res.findings)


def parse_vectormap_text(
    text: str, source: str = "<string>", *, scale: float = 1.0, checks: bool = True
) -> VectorMap:
    """Parse the text format (one ``x1, y1, x2, y2`` wall per line).

    Coordinates are multiplied by ``scale``, then checked (:mod:`autonomy.maps.map_hygiene`):
    findings are logged as warnings on ``"depthnav.map"``, errors raised as
    :class:`MapFormatError`. ``checks=False`` keeps only what a :class:`VectorMap` needs
    (drops zero-length segments; no duplicate, extent or overlap checks).
    """
    vm, findings = _parse_text(text, source, scale, checks)
    log_findings(findings)
    return vm


def _parse_text(text: str, source: str, scale: float, checks: bool) -> tuple[VectorMap, list[Finding]]:
    if text.startswith("\ufeff"):
        text = text[1:]
    vals: list[str] = []
    linenos: list[int] = []
    comma_match = _COMMA_LINE.fullmatch
    space_match = _SPACE_LINE.fullmatch
    for lineno, line in enumerate(text.split("\n"), 1):
        s = line.strip(_WS_CHARS)
        if not s or s[0] == "#":
            continue
        m = comma_match(s) if "," in s else space_match(s)
        if m is None:
            raise _diagnose_text_line(s, lineno, source)
        vals.extend(m.groups())
        linenos.append(lineno)
    if not linenos:
        raise _fail(source, None, f"no wall segments (expected lines of 4 numbers {_FIELDS})")
    arr = np.fromiter(map(float, vals), dtype=np.float64, count=len(vals)).reshape(-1, 4)
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():  # e.g. 1e999 overflows to inf
        i = int(np.flatnonzero(bad)[0])
        raise _fail(source, linenos[i], f"expected finite numbers {_FIELDS}, got {arr[i].tolist()}")
    return _finish(arr, linenos, source, "line(s)", scale, checks)


def format_vectormap_text(vm: VectorMap) -> str:
    """Text format with repr-exact floats (parses back bit for bit)."""
    r = float.__repr__
    return "".join(
        f"{r(a)}, {r(b)}, {r(c)}, {r(d)}\n" for a, b, c, d in vm.segments.tolist()
    )


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


def _fast_point(p: Any) -> tuple[float, float] | None:
    """(x, y) of a well-formed point object, or None to trigger the slow, explaining path."""
    if type(p) is not dict:
        return None
    x = p.get("x")
    y = p.get("y")
    if type(x) not in (float, int) or type(y) not in (float, int):
        return None
    try:
        return float(x), float(y)
    except OverflowError:
        return None


def parse_vectormap_json(
    text: str, source: str = "<string>", *, scale: float = 1.0, checks: bool = True
) -> VectorMap:
    """Parse the JSON format ``[{"p0": {"x", "y"}, "p1": {"x", "y"}}, ...]``.

    ``scale`` and ``checks`` as for :func:`parse_vectormap_text`; findings name elements
    as ``[i] (line L)``.
    """
    vm, findings = _parse_json(text, source, scale, checks)
    log_findings(findings)
    return vm


def _parse_json(text: str, source: str, scale: float, checks: bool) -> tuple[VectorMap, list[Finding]]:
    data = _json_load(text, source)
    ctx = _JsonCtx(text, source)
    if not isinstance(data, list):
        hint = " (is this a navigation graph?)" if isinstance(data, dict) and "nodes" in data else ""
        raise ctx.fail([], f'expected an array of {{"p0": {{"x", "y"}}, "p1": {{"x", "y"}}}} segments, got {_json_type(data)}{hint}')
    rows: list[tuple[float, float, float, float]] = []
    for i, el in enumerate(data):
        a = b = None
        if type(el) is dict:
            a = _fast_point(el.get("p0"))
            b = _fast_point(el.get("p1"))
        if a is None or b is None:
            d = ctx.obj(el, [i], 'a segment object {"p0": {...}, "p1": {...}}')
            pts = []
            for k in ("p0", "p1"):
                p = ctx.obj(ctx.key(d, k, [i]), [i, k], 'a point object {"x": .., "y": ..}')
                pts.append(
                    (ctx.number(ctx.key(p, "x", [i, k]), [i, k, "x"]),
                     ctx.number(ctx.key(p, "y", [i, k]), [i, k, "y"]))
                )
            a, b = pts
        rows.append((a[0], a[1], b[0], b[1]))
    if not rows:
        raise _fail(source, None, "no wall segments (expected a non-empty array)")
    arr = np.array(rows, dtype=np.float64)
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        el = data[i]
        for k in ("p0", "p1"):
            for c in ("x", "y"):
                ctx.number(el[k][c], [i, k, c])
    return _finish(arr, _LazyElementLines(text, len(rows)), source, "element(s)", scale, checks)


class _LazyElementLines:
    """``lines[i]`` -> ``"[i] (line L)"`` for messages, computed only when asked.

    The element start offsets are found by one walk over the top-level array, extended as
    far as the largest index asked for (a message lists only a few elements).
    """

    def __init__(self, text: str, n: int):
        self.text = text
        self.n = n
        self._starts: list[int] = []
        self._pos: int | None = None  # where the walk goes on; -1 once it cannot
        self._dec = json.JSONDecoder()

    def _start(self, i: int) -> int | None:
        text = self.text
        if self._pos is None:
            p = _skip_ws(text, 1 if text.startswith("\ufeff") else 0)
            self._pos = _skip_ws(text, p + 1) if p < len(text) and text[p] == "[" else -1
        try:
            while len(self._starts) <= i and self._pos >= 0:
                self._starts.append(self._pos)
                _, p = self._dec.raw_decode(text, self._pos)
                p = _skip_ws(text, p)
                self._pos = _skip_ws(text, p + 1) if p < len(text) and text[p] == "," else -1
        except ValueError:
            self._pos = -1
        return self._starts[i] if i < len(self._starts) else None

    def __getitem__(self, i: int) -> str:
        off = self._start(int(i))
        return f"[{i}]" if off is None else f"[{i}] (line {self.text.count(chr(10), 0, off) + 1})"


def format_vectormap_json(vm: VectorMap) -> str:
    """JSON format, one segment per line, repr-exact floats."""
    r = float.__repr__
    rows = [
        f'{{"p0": {{"x": {r(a)}, "y": {r(b)}}}, "p1": {{"x": {r(c)}, "y": {r(d)}}}}}'
        for a, b, c, d in vm.segments.tolist()
    ]
    return "[\n" + ",\n".join(rows) + ("\n]\n" if rows else "]\n")


# --------------------------------------------------------------------------- file I/O


def _stem_name(source: str) -> str:
    if source.startswith("<"):
        return ""
    name = Path(source).name
    for suf in (".vectormap.txt", ".vectormap.json", ".navigation.json", "_vector.txt", ".txt", ".json"):
        if name.lower().endswith(suf):
            return name[: -len(suf)]
    return name


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


def _suffix_kind(path: PathLike) -> str:
    name = Path(path).name.lower()
    if name.endswith(TEXT_SUFFIXES):
        return "text"
    if name.endswith(JSON_SUFFIXES):
        return "json"
    raise _fail(
        os.fspath(path),
        None,
        "unknown vector map suffix, expected .txt (e.g. *.vectormap.txt, *_vector.txt) "
        "or .json (e.g. *.vectormap.json)",
    )


def load_vectormap(path: PathLike, *, scale: float = 1.0, checks: bool = True) -> VectorMap:
    """Load a vector map, choosing the format from the suffix (``.txt`` or ``.json``).

    Coordinates are multiplied by ``scale`` (0.001 for a map in millimetres), then checked
    (:mod:`autonomy.maps.map_hygiene`): each finding is logged as one warning line on the
    ``"depthnav.map"`` logger; an error raises :class:`MapFormatError`.
    """
    vm, findings = load_vectormap_checked(path, scale=scale, checks=checks)
    log_findings(findings)
    return vm


def load_vectormap_checked(
    path: PathLike, *, scale: float = 1.0, checks: bool = True
) -> tuple[VectorMap, list[Finding]]:
    """:func:`load_vectormap` that returns the findings (file line numbers) instead of logging them."""
    kind = _suffix_kind(path)
    text, source = _read_text(path)
    if kind == "text":
        return _parse_text(text, source, scale, checks)
    return _parse_json(text, source, scale, checks)


def save_vectormap(vm: VectorMap, path: PathLike) -> Path:
    """Write a vector map in the format given by the suffix; returns the path."""
    kind = _suffix_kind(path)
    text = format_vectormap_text(vm) if kind == "text" else format_vectormap_json(vm)
    p = Path(path)
    p.write_text(text, encoding="utf-8")
    return p


# --------------------------------------------------------------------------- navigation graph

DEFAULT_MAX_SPEED = 0.75
"""Default edge speed limit in m/s when a file leaves it out."""
DEFAULT_MAX_CLEARANCE = 1.0
"""Default edge clearance in metres when a file leaves it out."""


def _finite_float(v: Any, what: str) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a number, got {v!r}") from None
    if not math.isfinite(f):
        raise InputError(f"{what}: expected a finite number, got {v!r}")
    return f


@dataclass(frozen=True)
class NavNode:
    """A navigation-graph vertex."""

    id: int
    """Node id (unique in its graph; not necessarily contiguous)."""
    x: float
    """World x in metres."""
    y: float
    """World y in metres."""

    def __post_init__(self) -> None:
        if isinstance(self.id, bool) or not isinstance(self.id, int | np.integer):
            raise InputError(f"nav node: id must be an integer, got {self.id!r}")
        object.__setattr__(self, "id", int(self.id))
        object.__setattr__(self, "x", _finite_float(self.x, f"nav node {self.id} x"))
        object.__setattr__(self, "y", _finite_float(self.y, f"nav node {self.id} y"))


@dataclass(frozen=True)
class NavEdge:
    """An undirected navigation-graph edge between two node ids."""

    s0_id: int
    """First node id."""
    s1_id: int
    """Second node id."""
    has_door: bool = False
    """The edge passes through a doorway."""
    has_stairs: bool = False
    """The edge uses stairs."""
    has_elevator: bool = False
    """The edge uses an elevator."""
    has_automated_door: bool = False
    """The edge passes an automated door."""
    max_speed: float = DEFAULT_MAX_SPEED
    """Speed limit on this edge in m/s."""
    max_clearance: float = DEFAULT_MAX_CLEARANCE
    """Free half-width either side of the edge in metres."""

    def __post_init__(self) -> None:
        for k in ("s0_id", "s1_id"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, int | np.integer):
                raise InputError(f"nav edge: {k} must be an integer, got {v!r}")
            object.__setattr__(self, k, int(v))
        for k in ("has_door", "has_stairs", "has_elevator", "has_automated_door"):
            object.__setattr__(self, k, bool(getattr(self, k)))
        for k in ("max_speed", "max_clearance"):
            v = _finite_float(getattr(self, k), f"nav edge {self.s0_id}-{self.s1_id} {k}")
            if v < 0:
                raise InputError(f"nav edge {self.s0_id}-{self.s1_id} {k}: must be >= 0, got {v}")
            object.__setattr__(self, k, v)


_EDGE_FLAGS = ("has_door", "has_stairs", "has_elevator", "has_automated_door")


@dataclass(frozen=True)
class NavGraph:
    """An undirected navigation graph (UT AMRL ``*.navigation.json``)."""

    nodes: tuple[NavNode, ...]
    """Vertices, in file order."""
    edges: tuple[NavEdge, ...] = ()
    """Undirected edges between node ids."""
    _index: dict[int, int] = field(init=False, repr=False, compare=False)
    _adj: tuple[tuple[int, ...], ...] = field(init=False, repr=False, compare=False)
    _xy: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        nodes = tuple(self.nodes)
        edges = tuple(self.edges)
        if not nodes:
            raise InputError("nav graph: no nodes")
        index: dict[int, int] = {}
        for i, n in enumerate(nodes):
            if not isinstance(n, NavNode):
                raise InputError(f"nav graph: nodes[{i}] is not a NavNode")
            if n.id in index:
                raise InputError(f"nav graph: nodes[{i}] duplicates node id {n.id} (first at nodes[{index[n.id]}])")
            index[n.id] = i
        adj: list[list[int]] = [[] for _ in nodes]
        for j, e in enumerate(edges):
            if not isinstance(e, NavEdge):
                raise InputError(f"nav graph: edges[{j}] is not a NavEdge")
            for k in ("s0_id", "s1_id"):
                if getattr(e, k) not in index:
                    raise InputError(f"nav graph: edges[{j}].{k} names unknown node id {getattr(e, k)}")
            a, b = index[e.s0_id], index[e.s1_id]
            adj[a].append(e.s1_id)
            if a != b:
                adj[b].append(e.s0_id)
        xy = np.array([(n.x, n.y) for n in nodes], dtype=np.float64).reshape(-1, 2)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "edges", edges)
        object.__setattr__(self, "_index", index)
        object.__setattr__(self, "_adj", tuple(tuple(a) for a in adj))
        object.__setattr__(self, "_xy", _readonly(xy))

    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return len(self.nodes)

    @property
    def n_edges(self) -> int:
        """Number of edges."""
        return len(self.edges)

    def node_xy(self) -> np.ndarray:
        """(N, 2) node positions in node order (read-only)."""
        return self._xy

    def node_ids(self) -> np.ndarray:
        """(N,) node ids in node order."""
        return np.array([n.id for n in self.nodes], dtype=np.int64)

    def index_of(self, node_id: int) -> int:
        """Position of a node id in :attr:`nodes`; InputError if unknown."""
        try:
            return self._index[int(node_id)]
        except (KeyError, TypeError, ValueError):
            raise InputError(f"nav graph: unknown node id {node_id!r}") from None

    def node(self, node_id: int) -> NavNode:
        """The node with this id."""
        return self.nodes[self.index_of(node_id)]

    def neighbors(self, node_id: int) -> list[int]:
        """Ids of the nodes joined to ``node_id`` by an edge, in edge order."""
        return list(self._adj[self.index_of(node_id)])

    def nearest_node(self, x: float, y: float) -> int:
        """Id of the node closest to ``(x, y)``."""
        d2 = (self._xy[:, 0] - x) ** 2 + (self._xy[:, 1] - y) ** 2
        return self.nodes[int(np.argmin(d2))].id

    def edge_indices(self) -> np.ndarray:
        """(E, 2) int64 node *indices* (positions in :attr:`nodes`) of each edge."""
        return np.array(
            [(self._index[e.s0_id], self._index[e.s1_id]) for e in self.edges], dtype=np.int64
        ).reshape(-1, 2)

    def edge_segments(self) -> np.ndarray:
        """(E, 4) edges as segments ``x1, y1, x2, y2``."""
        ij = self.edge_indices()
        return np.concatenate([self._xy[ij[:, 0]], self._xy[ij[:, 1]]], axis=1).reshape(-1, 4)

    def __repr__(self) -> str:
        return f"NavGraph(n_nodes={self.n_nodes}, n_edges={self.n_edges})"

    def edge_lengths(self) -> np.ndarray:
        """(E,) edge lengths in metres."""
        s = self.edge_segments()
        return np.hypot(s[:, 2] - s[:, 0], s[:, 3] - s[:, 1])


def parse_navgraph_json(text: str, source: str = "<string>") -> NavGraph:
    """Parse a UT AMRL navigation graph (``{"nodes": [...], "edges": [...]}``)."""
    data = _json_load(text, source)
    ctx = _JsonCtx(text, source)
    top = ctx.obj(data, [], 'an object {"nodes": [...], "edges": [...]}')
    raw_nodes = ctx.key(top, "nodes", [])
    raw_edges = ctx.key(top, "edges", [])
    if not isinstance(raw_nodes, list):
        raise ctx.fail(["nodes"], f"expected an array of nodes, got {_json_type(raw_nodes)}")
    if not isinstance(raw_edges, list):
        raise ctx.fail(["edges"], f"expected an array of edges, got {_json_type(raw_edges)}")
    if not raw_nodes:
        raise ctx.fail(["nodes"], "expected at least one node, got an empty array")
    nodes: list[NavNode] = []
    first: dict[int, int] = {}
    for i, rn in enumerate(raw_nodes):
        p: list[int | str] = ["nodes", i]
        d = ctx.obj(rn, p, 'a node object {"id": int, "loc": {"x": .., "y": ..}}')
        nid = ctx.integer(ctx.key(d, "id", p), p + ["id"])
        loc = ctx.obj(ctx.key(d, "loc", p), p + ["loc"], 'a point object {"x": .., "y": ..}')
        x = ctx.number(ctx.key(loc, "x", p + ["loc"]), p + ["loc", "x"])
        y = ctx.number(ctx.key(loc, "y", p + ["loc"]), p + ["loc", "y"])
        if nid in first:
            raise ctx.fail(p + ["id"], f"duplicate node id {nid} (first at nodes[{first[nid]}])")
        first[nid] = i
        nodes.append(NavNode(nid, x, y))
    edges: list[NavEdge] = []
    for j, re_ in enumerate(raw_edges):
        p = ["edges", j]
        d = ctx.obj(re_, p, 'an edge object {"s0_id": int, "s1_id": int, ...}')
        ids = []
        for k in ("s0_id", "s1_id"):
            v = ctx.integer(ctx.key(d, k, p), p + [k])
            if v not in first:
                raise ctx.fail(p + [k], f"unknown node id {v} (edge {j} must join existing nodes)")
            ids.append(v)
        kw: dict[str, Any] = {}
        for k in _EDGE_FLAGS:
            if k in d:
                kw[k] = ctx.boolean(d[k], p + [k])
        for k in ("max_speed", "max_clearance"):
            if k in d:
                v = ctx.number(d[k], p + [k])
                if v < 0:
                    raise ctx.fail(p + [k], f"expected a number >= 0, got {v!r}")
                kw[k] = v
        edges.append(NavEdge(ids[0], ids[1], **kw))
    return NavGraph(tuple(nodes), tuple(edges))


def format_navgraph_json(g: NavGraph) -> str:
    """JSON text of a navigation graph, one node / edge per line, repr-exact floats."""
    node_rows = [
        json.dumps({"id": n.id, "loc": {"x": n.x, "y": n.y}}) for n in g.nodes
    ]
    edge_rows = [
        json.dumps(
            {
                "s0_id": e.s0_id,
                "s1_id": e.s1_id,
                "has_door": e.has_door,
                "has_stairs": e.has_stairs,
                "has_elevator": e.has_elevator,
                "has_automated_door": e.has_automated_door,
                "max_speed": e.max_speed,
                "max_clearance": e.max_clearance,
            }
        )
        for e in g.edges
    ]

    def block(rows: list[str]) -> str:
        return "[\n    " + ",\n    ".join(rows) + "\n  ]" if rows else "[]"

    return '{\n  "nodes": ' + block(node_rows) + ',\n  "edges": ' + block(edge_rows) + "\n}\n"


def load_navgraph(path: PathLike) -> NavGraph:
    """Load a ``*.navigation.json`` file."""
    text, source = _read_text(path)
    return parse_navgraph_json(text, source)


def save_navgraph(g: NavGraph, path: PathLike) -> Path:
    """Write a navigation graph as JSON; returns the path."""
    p = Path(path)
    p.write_text(format_navgraph_json(g), encoding="utf-8")
    return p


def check_vectormap(vm: VectorMap, source: str | None = None) -> list[Finding]:
    """The findings for a map already in memory (segments named ``[i]``, 0-based).

    Nothing is changed or logged; messages say "would drop". ``source`` defaults to the
    map's name. A map loaded from a file has had its zero-length and duplicate segments
    dropped already, so this mostly reports overlaps and the extent.
    """
    name = source if source is not None else (vm.name or "vector map")
    return list(clean_segments(vm.segments, name, applied=False).findings)
