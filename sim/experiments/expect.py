"""Expectations: what a scenario must achieve, checked on its report.

A scenario's ``[expect]`` table maps report metrics (``report.json``'s ``metrics``, listed
in :data:`sim.experiments.metric_names.METRICS`) to what they must be::

    [expect]
    collisions = 0                   # a bare number: exactly this
    waypoints_failed = 0
    loc_error_p95_m = "< 0.10"       # a comparison: <, <=, >, >=, == or != and a number
    realtime_factor = "> 1"

Every expectation is checked at the end of a run and on every trial of a sweep; the
report's ``expect`` block says which held, and the CLI exits with
:data:`EXPECTATION_FAILED` when one did not (neither success, 0, nor a user error, 2).
A metric the run did not measure (``loc_error_p95_m`` with localization off) fails its
expectation: it was not shown to hold.
"""

from __future__ import annotations

import difflib
import math
import operator
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from autonomy.common.errors import InputError

#: Exit code of a run, sweep or test whose expectations did not all hold.
EXPECTATION_FAILED = 3

_OPS: dict[str, Callable[[float, float], bool]] = {
    "<=": operator.le, ">=": operator.ge, "==": operator.eq, "!=": operator.ne, "<": operator.lt, ">": operator.gt,
}
_FORM = re.compile(r"^\s*(<=|>=|==|!=|<|>)?\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*$")


@dataclass(frozen=True)
class Expectation:
    """One ``metric op value`` condition."""

    metric: str
    op: str
    value: float

    def __str__(self) -> str:
        return f"{self.metric} {self.op} {self.value:g}"

    def holds(self, actual: Any) -> bool:
        """Whether a measured value meets it (a missing or non-numeric value does not)."""
        if isinstance(actual, bool) or not isinstance(actual, (int, float)) or math.isnan(actual):
            return False
        return bool(_OPS[self.op](float(actual), self.value))


def parse_expectation(metric: str, spec: Any, source: str, known: Mapping[str, str]) -> Expectation:
    """``[expect]``'s ``metric = spec`` as an :class:`Expectation`, or an InputError
    naming ``source``, the key and what was expected."""
    key = f"expect.{metric}"
    if metric not in known:
        close = difflib.get_close_matches(metric, list(known), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(f"{source}: key '{key}': no such report metric{hint}; the metrics are listed in docs/scenario_tests.md#metrics")
    if isinstance(spec, bool) or not isinstance(spec, (int, float, str)):
        raise InputError(f"{source}: key '{key}' expected a number or a comparison such as \"< 0.10\", got {spec!r}")
    if isinstance(spec, str):
        m = _FORM.match(spec)
        if m is None:
            raise InputError(f"{source}: key '{key}' expected a comparison such as \"< 0.10\" (<, <=, >, >=, == or != and a number), got {spec!r}")
        op, value = m.group(1) or "==", float(m.group(2))
    else:
        op, value = "==", float(spec)
    if not math.isfinite(value):
        raise InputError(f"{source}: key '{key}' expected a finite number, got {spec!r}")
    return Expectation(metric, op, value)


def parse_expectations(table: Any, source: str, known: Mapping[str, str] | None = None) -> tuple[Expectation, ...]:
    """A scenario's ``[expect]`` table, in the file's order."""
    if known is None:
        from sim.experiments.metric_names import METRICS as known
    if not isinstance(table, dict):
        raise InputError(f"{source}: key 'expect' expected a table of metric = condition, got {table!r}")
    return tuple(parse_expectation(str(k), v, source, known) for k, v in table.items())


def check(expectations: tuple[Expectation, ...], metrics: Mapping[str, Any]) -> dict:
    """The report's ``expect`` block: every expectation with the measured value and
    whether it held, and whether all did (True with none)."""
    checks = []
    for e in expectations:
        actual = metrics.get(e.metric)
        checks.append({"metric": e.metric, "expected": f"{e.op} {e.value:g}", "actual": actual, "held": e.holds(actual)})
    return {"passed": all(c["held"] for c in checks), "checks": checks}


def failures(block: Mapping[str, Any]) -> list[str]:
    """The failed checks of an ``expect`` block as ``metric = actual (expected op value)``."""
    out = []
    for c in block.get("checks", []):
        if not c["held"]:
            got = "not measured" if c["actual"] is None else f"{c['actual']:g}" if isinstance(c["actual"], (int, float)) else repr(c["actual"])
            out.append(f"{c['metric']} = {got} (expected {c['expected']})")
    return out


def summary_line(name: str, block: Mapping[str, Any]) -> str:
    """One line for the terminal: how many expectations held, and the failed ones."""
    n = len(block.get("checks", []))
    failed = failures(block)
    if not failed:
        return f"{name}: expectations: all {n} held"
    return f"{name}: expectations: {len(failed)} of {n} failed: " + "; ".join(failed)
