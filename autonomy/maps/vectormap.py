"""Vector maps (walls as 2D line segments) and their file formats.

Formats (CoBot / UT AMRL, docs/architecture.md):

- Text vector map (``*.vectormap.txt``, ``*_vector.txt``, any ``.txt``): one wall per
  line, ``x1, y1, x2, y2`` in metres. Commas with optional spaces, or plain whitespace.
  Blank lines and lines starting with ``#`` are skipped.
- JSON vector map (``*.vectormap.json``, any ``.json``):
  ``[{"p0": {"x": .., "y": ..}, "p1": {"x": .., "y": ..}}, ...]``.

Every malformed input raises :class:`MapFormatError`, whose one-line message names the
file, the line (and for JSON the element path, e.g. ``[3].p1.y``) and what was expected.

Loading also checks the walls (:mod:`autonomy.maps.map_hygiene`): zero-length and duplicate
segments are dropped, overlapping collinear ones reported, and a map whose extent is not a
building in metres (a millimetre map, say) refused. Each finding is one warning line on the
``"depthnav.map"`` logger; ``load_vectormap(path, scale=0.001)`` reads a millimetre map.

The navigation graph (:mod:`autonomy.maps.navgraph`) is re-exported here beside the map,
as the pair of files a site loads: ``from autonomy.maps.vectormap import load_navgraph,
load_vectormap``.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.map_files import (
    MapFormatError,
    PathLike,
    _fail,
    _json_load,
    _json_type,
    _JsonCtx,
    _read_text,
    _readonly,
    _short,
    _skip_ws,
)
from autonomy.maps.map_hygiene import Finding, clean_segments, log_findings
from autonomy.maps.navgraph import (
    NavEdge,
    NavGraph,
    NavNode,
    format_navgraph_json,
    load_navgraph,
    parse_navgraph_json,
    save_navgraph,
)

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


def check_vectormap(vm: VectorMap, source: str | None = None) -> list[Finding]:
    """The findings for a map already in memory (segments named ``[i]``, 0-based).

    Nothing is changed or logged; messages say "would drop". ``source`` defaults to the
    map's name. A map loaded from a file has had its zero-length and duplicate segments
    dropped already, so this mostly reports overlaps and the extent.
    """
    name = source if source is not None else (vm.name or "vector map")
    return list(clean_segments(vm.segments, name, applied=False).findings)
