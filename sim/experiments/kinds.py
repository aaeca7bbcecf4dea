"""Experiment kinds: every scenario file names one, and each kind knows how to run and sweep.

A scenario TOML may start with ``kind = "..."`` (default ``"mission"``, the waypoint runs
of :mod:`sim.experiments.runner`). A kind is an :class:`Experiment`: the frozen dataclass its file is
parsed into, a ``run`` that writes ``report.json`` (and figures) for one invocation, and
the three parts a sweep needs — ``trials`` (the seeded trial specs of an ``n``-trial
sweep), ``trial`` (one spec in, one JSON-able result out; a plain module-level function so
process pools and Ray can ship it) and ``summarize`` (all results in, ``report.json`` out).

Kinds are looked up lazily by module so that ``depthnav run`` of one kind imports only
what that kind needs.
"""

from __future__ import annotations

import dataclasses
import importlib
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autonomy.common.errors import InputError
from sim.config import apply_overrides, from_dict, read_toml

#: kind → module that defines ``EXPERIMENTS[kind]``.
KINDS: dict[str, str] = {
    "mission": "sim.experiments.mission",
    "localization_comparison": "sim.experiments.loc_compare",
    "mapping_cuboid": "sim.experiments.mapping.cuboid",
    "mapping_wall": "sim.experiments.mapping.wall",
    "mapping_corridor": "sim.experiments.mapping.corridor",
    "real_floors": "sim.experiments.real_floors",
}


class RunCrashed(RuntimeError):
    """An experiment's loop stopped on an error (``what``: where and which); the report
    of what it finished was written first (``report_path``), the traceback beside it in
    ``crash.txt``."""

    def __init__(self, what: str, report_path: str) -> None:
        super().__init__(what, report_path)
        self.what, self.report_path = what, report_path

    def __str__(self) -> str:
        traceback_path = Path(self.report_path).with_name(CRASH_FILE)
        return f"{self.what}; what it finished is in {self.report_path}, the traceback in {traceback_path}"


#: Where a run stopped by an error writes the traceback, beside its report.
CRASH_FILE = "crash.txt"


def crash_block(exc: BaseException) -> dict:
    """The report's ``error`` block for ``exc``: its type, the first line of its
    message and where the traceback is."""
    text = str(exc).strip()
    return {"type": type(exc).__name__, "message": text.splitlines()[0] if text else "", "traceback_file": CRASH_FILE}


def write_crash(out_dir: Path, exc: BaseException) -> None:
    """Write ``exc``'s traceback to ``CRASH_FILE`` in ``out_dir``."""
    (Path(out_dir) / CRASH_FILE).write_text("".join(traceback.format_exception(exc)), encoding="utf-8")


def stopped(exc: BaseException, where: str, report_path: Path) -> Exception:
    """What a run stopped by ``exc`` raises once its report is written: a user's mistake
    found only on the way stays the one-line :class:`InputError` (exit 2), with where
    the finished part was kept; anything else is :class:`RunCrashed` (exit 1)."""
    msg = crash_block(exc)["message"]
    if isinstance(exc, InputError):
        return InputError(f"{msg} ({where}; what it finished is in {report_path})")
    return RunCrashed(f"{where} on an error: {type(exc).__name__}: {msg}", str(report_path))


@dataclass(frozen=True)
class Experiment:
    """What a scenario kind provides (see the module docstring)."""

    kind: str
    config_type: type
    """Frozen dataclass with at least ``name``, ``description``, ``seed`` and ``base_dir``."""
    run: Callable[..., dict]
    """``run(cfg, out_dir, *, seed=None, rrd=None, spawn=False, progress=None) -> report``;
    the report has ``metrics`` (flat dict) and ``interrupted`` (bool)."""
    trials: Callable[[Any, int, int], list[dict]]
    """``trials(cfg, n, seed) -> [spec, ...]``; each spec is JSON-able with a unique ``id``."""
    trial: Callable[[Any, dict], dict]
    """``trial(cfg, spec) -> result`` (JSON-able), deterministic for a spec."""
    summarize: Callable[[Any, list[dict], Path], dict]
    """``summarize(cfg, results, out_dir) -> report``; writes report.json and figures."""


def experiment(kind: str, source: str = "") -> Experiment:
    """The :class:`Experiment` registered for ``kind`` (InputError naming ``source`` if none)."""
    if kind not in KINDS:
        raise InputError(f"{source}: key 'kind': unknown experiment kind {kind!r} (expected one of: {', '.join(KINDS)})")
    module = importlib.import_module(KINDS[kind])
    return module.EXPERIMENTS[kind]


def shipped_scenario(path: Path) -> Path:
    """``path``, or for a bare name that is not a file here, the project's scenario of
    that name (with or without ``.toml``) when there is one."""
    from sim.scenario import SCENARIOS_DIR

    if path.exists() or len(path.parts) != 1:
        return path
    for cand in (SCENARIOS_DIR / path.name, SCENARIOS_DIR / f"{path.name}.toml"):
        if cand.is_file():
            return cand
    return path


def load_experiment(path: str | Path, overrides: list[str] | None = None) -> tuple[Experiment, Any]:
    """Read a scenario file of any kind: (its Experiment, its parsed config). A bare name
    that is not a file here (``demo.toml`` or ``demo``) is looked up among the project's
    scenarios, the ones ``depthnav scenarios`` lists."""
    path = shipped_scenario(Path(path))
    src = str(path)
    data = read_toml(path)
    kind = data.pop("kind", "mission")
    if not isinstance(kind, str):
        raise InputError(f"{src}: key 'kind' expected a string, got {kind!r}")
    exp = experiment(kind, src)
    if kind == "mission":
        from sim.scenario import load_scenario

        return exp, load_scenario(path, overrides)
    if "base_dir" in data:
        raise InputError(f"{src}: unknown key 'base_dir' (it is set from the file's location)")
    data = apply_overrides(data, overrides or [])
    data["base_dir"] = str(path.resolve().parent)
    if "expect" in data and "expect" in {f.name for f in dataclasses.fields(exp.config_type)}:
        from sim.scenario import with_expectations

        return exp, with_expectations(from_dict, exp.config_type, data, src)
    return exp, from_dict(exp.config_type, data, source=src)
