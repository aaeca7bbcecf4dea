"""Sweeps: many seeded trials of any experiment kind, on this machine or on a Ray cluster.

``depthnav sweep SCENARIO.toml [--trials N] [--engine local|ray] [--address ADDR]
[--workers K] [--out DIR] [--resume]`` asks the scenario's kind (:mod:`sim.experiments.kinds`)
for ``N`` seeded trial specs, runs each with the kind's ``trial`` and hands all results
to its ``summarize`` (report.json and figures). Engines (:mod:`sim.experiments.sweep_engines`):

- ``local`` (default): a process pool (spawn start method) of ``K`` workers on this
  machine (``K = 1`` runs the trials in this process); nothing else needed.
- ``ray``: the same trials as Ray tasks (``max_retries`` for lost workers) on the
  cluster at ``--address``, or on a local Ray instance with ``K`` CPUs when no address
  is given. Ray is imported only here (``pip install 'depthnav[ray]'``).

Workers receive (scenario path, overrides, spec) and parse the scenario themselves
(:func:`sim.experiments.kinds.load_experiment`; parsed once per process), so every node
needs the project installed and the scenario file at the same path. ``depthnav run``
of a sweepable kind ships the parsed config instead.

Bookkeeping in the output directory: ``sweep.json`` (kind, scenario, overrides, trial
count, seed and a hash of the parsed config) and ``trials.jsonl``, one line per finished
trial (``{"id", "spec", "result", "wall_s", "host", "pid"}``), appended, flushed and
fsynced as each trial finishes. ``--resume`` checks that ``sweep.json`` describes the
same sweep, keeps every finished trial and runs only the others; a line cut short by a
kill is dropped. Ctrl-C stops the sweep, keeps what finished and prints how to resume.
A kind whose module defines ``prepare(cfg, progress)`` (e.g. record a log once) has it
called in this process before any trial is dispatched.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import json
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write_text
from sim.config import to_dict
from sim.experiments.expect import check, failures
from sim.experiments.kinds import KINDS, Experiment, load_experiment
from sim.experiments.report_file import config_json, write_json
from sim.experiments.sweep_engines import ray_session, run_local, run_ray

ENGINES = ("local", "ray")
SWEEP_VERSION = 1
#: Default trial count for kinds whose config has no ``replays``.
DEFAULT_TRIALS = 10


class SweepError(RuntimeError):
    """Some trials raised; the finished ones are kept, the sweep can be resumed."""


# --------------------------------------------------------------------------- bookkeeping


def config_hash(cfg: Any) -> str:
    d = to_dict(cfg)
    if isinstance(d, dict):
        d = {k: v for k, v in d.items() if k != "base_dir"}
    return hashlib.sha256(json.dumps(config_json(d), sort_keys=True).encode()).hexdigest()[:16]


def read_trials(path: Path, ids: set[str] | None = None) -> tuple[dict[str, dict], bool]:
    """Finished trials from a trials.jsonl (first record per id; unparsable lines, e.g. a
    line cut short by a kill, are skipped); and whether any line was skipped."""
    done: dict[str, dict] = {}
    skipped = False
    if not path.is_file():
        return done, False
    with open(path, encoding="utf-8") as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                skipped = True
                continue
            if not isinstance(rec, dict) or "id" not in rec or "result" not in rec:
                skipped = True
                continue
            if ids is not None and rec["id"] not in ids:
                skipped = True
                continue
            if rec["id"] in done:
                skipped = True
                continue
            done[rec["id"]] = rec
    return done, skipped


def _rewrite(path: Path, records: list[dict]) -> None:
    atomic_write_text(path, "".join(json.dumps(r) + "\n" for r in records))


class _Appender:
    def __init__(self, path: Path) -> None:
        self.f = open(path, "a", encoding="utf-8")

    def write(self, rec: dict) -> None:
        self.f.write(json.dumps(rec) + "\n")
        self.f.flush()
        os.fsync(self.f.fileno())

    def close(self) -> None:
        self.f.close()


# --------------------------------------------------------------------------- the sweep


def default_trials(cfg: Any) -> int:
    n = getattr(cfg, "replays", None)
    return int(n) if isinstance(n, int) and n > 0 else DEFAULT_TRIALS


#: The ``sweep.json`` keys that must match for a directory to hold the same sweep.
_SAME_SWEEP_KEYS = ("version", "kind", "trials", "seed", "config_hash")


@dataclass
class _Sweep:
    """One sweep as :func:`run_experiment` set it up: what to run, where, and how."""

    exp: Experiment
    cfg: Any
    out: Path
    specs: list[dict]
    meta: dict
    """What ``sweep.json`` records."""
    engine: str
    workers: int
    address: str | None
    source: tuple
    """How workers get the config: ``("config", cfg)`` or ``("path", scenario, overrides)``."""
    hint: str
    """The command that resumes this sweep."""

    @property
    def trials_path(self) -> Path:
        return self.out / "trials.jsonl"

    @property
    def ids(self) -> list[str]:
        return [s["id"] for s in self.specs]


def _check_args(cfg: Any, engine: str, trials: int | None, workers: int | None, address: str | None) -> int:
    """Check the sweep's options; the number of trials."""
    if engine not in ENGINES:
        raise InputError(f"--engine {engine!r}: expected one of {', '.join(ENGINES)}")
    n = default_trials(cfg) if trials is None else int(trials)
    if n < 1:
        raise InputError(f"--trials {trials}: expected an integer >= 1")
    if workers is not None and workers < 1:
        raise InputError(f"--workers {workers}: expected an integer >= 1")
    if address and engine != "ray":
        raise InputError("--address: only with --engine ray")
    return n


def _trial_specs(exp: Experiment, cfg: Any, n: int, seed: int) -> list[dict]:
    specs = exp.trials(cfg, n, seed)
    ids = [s["id"] for s in specs]
    if len(set(ids)) != len(ids):
        raise RuntimeError(f"experiment kind {exp.kind!r} produced duplicate trial ids")
    return specs


def _read_meta(path: Path) -> dict | None:
    """The ``sweep.json`` already in the output directory, if it is readable."""
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None


def _finished_trials(sw: _Sweep, resume: bool | str) -> dict[str, dict]:
    """Check ``resume`` against what the output directory holds, drop what this sweep
    cannot use, write ``sweep.json``; the finished trials this sweep keeps, by id."""
    meta_path, trials_path, meta, out = sw.out / "sweep.json", sw.trials_path, sw.meta, sw.out
    old = _read_meta(meta_path)
    same = old is not None and all(old.get(k) == meta[k] for k in _SAME_SWEEP_KEYS)
    if resume is True:
        if old is not None and not same:
            diff = [k for k in ("kind", "trials", "seed", "config_hash") if old.get(k) != meta[k]]
            what = ", ".join(f"{k} {old.get(k)!r} there vs {meta[k]!r} now" for k in diff) or "an older sweep format"
            raise InputError(f"--resume: {out} holds a different sweep ({what})")
    elif resume == "auto":
        if not same:
            trials_path.unlink(missing_ok=True)
    else:
        existing, _ = read_trials(trials_path)
        if existing:
            raise InputError(f"--out {out}: already holds a sweep with {len(existing)} finished trials (pass --resume to finish it, or choose another --out)")
    done: dict[str, dict] = {}
    if trials_path.is_file():
        done, skipped = read_trials(trials_path, set(sw.ids))
        if skipped:
            _rewrite(trials_path, list(done.values()))
    write_json(meta_path, meta)
    return done


def _prepare(kind_module: str, cfg: Any, progress: bool) -> None:
    """Call the kind module's ``prepare(cfg, progress)``, if it has one."""
    prep: Callable | None = getattr(importlib.import_module(kind_module), "prepare", None) if kind_module else None
    if prep is not None:
        prep(cfg, progress)


def _progress_bar(sw: _Sweep, initial: int):
    from tqdm import tqdm

    desc = f"{sw.meta['scenario']} ({sw.engine}, {sw.workers} workers)"
    return tqdm(total=len(sw.specs), initial=initial, unit="trial", desc=desc, file=sys.stderr, smoothing=0.05)


def _run_pending(
    sw: _Sweep, pending: list[dict], done: dict[str, dict], progress: bool
) -> tuple[list[tuple[str, str]], float, bool]:
    """Run the pending trials on the sweep's engine, appending each finished one to
    ``trials.jsonl`` and to ``done``; the failures (id, message), wall time and whether
    Ctrl-C stopped the run."""
    kind_module = KINDS.get(sw.exp.kind, "")
    with ray_session(sw.address, sw.workers) if pending and sw.engine == "ray" else contextlib.nullcontext():
        return _run_prepared(sw, pending, done, progress, kind_module)


def _run_prepared(
    sw: _Sweep, pending: list[dict], done: dict[str, dict], progress: bool, kind_module: str
) -> tuple[list[tuple[str, str]], float, bool]:
    """:func:`_run_pending` once the engine is up: the kind's preparation, then the trials."""
    if pending:
        _prepare(kind_module, sw.cfg, progress)
    bar = _progress_bar(sw, len(done)) if progress and pending else None
    errors: list[tuple[str, str]] = []
    appender = _Appender(sw.trials_path)

    def on_done(rec: dict) -> None:
        appender.write(rec)
        done[rec["id"]] = rec
        if bar is not None:
            bar.update(1)

    def on_error(spec: dict, exc: BaseException) -> None:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        errors.append((spec["id"], f"{type(exc).__name__}: {msg}"))
        print(f"depthnav sweep: trial {spec['id']} failed: {type(exc).__name__}: {msg}", file=sys.stderr)

    t0 = time.perf_counter()
    interrupted = False
    try:
        if pending:
            if sw.engine == "local":
                run_local(sw.source, sw.exp.kind, kind_module, pending, sw.workers, on_done, on_error)
            else:
                run_ray(sw.source, sw.exp.kind, kind_module, pending, sw.workers, sw.address, on_done, on_error)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        appender.close()
        if bar is not None:
            bar.close()
    return errors, time.perf_counter() - t0, interrupted


def _write_report(out: Path, report: dict) -> dict:
    write_json(out / "report.json", report)
    return report


def _interrupted_report(sw: _Sweep, wall: float) -> dict:
    """Report what a resume will find after Ctrl-C."""
    # Read the file, not the in-memory count: Ctrl-C can land between a record's write
    # and its count.
    done, _ = read_trials(sw.trials_path, set(sw.ids))
    n = len(sw.specs)
    print(f"interrupted: {len(done)} of {n} trials finished and kept in {sw.trials_path}; resume with: {sw.hint}", file=sys.stderr)
    partial = {
        "scenario": sw.meta["scenario"],
        "kind": sw.exp.kind,
        "interrupted": True,
        "metrics": {"trials_done": len(done), "trials_total": n},
        "resume": sw.hint,
        "sweep": {"engine": sw.engine, "workers": sw.workers, "trials": n, "trials_file": sw.trials_path.name, "out_dir": str(sw.out), "wall_s": round(wall, 2)},
    }
    return _write_report(sw.out, partial)


def _final_report(sw: _Sweep, done: dict[str, dict], run_now: int, resumed: int, wall: float) -> dict:
    """The kind's summary of all trials, with the sweep's bookkeeping added."""
    results = [done[i]["result"] for i in sw.ids]
    report = sw.exp.summarize(sw.cfg, results, sw.out)
    report["sweep"] = {
        "engine": sw.engine,
        "workers": sw.workers,
        "address": sw.address,
        "trials": len(sw.specs),
        "run_now": run_now,
        "resumed": resumed,
        "seed": sw.meta["seed"],
        "wall_s": round(wall, 2),
        "trials_file": sw.trials_path.name,
        "out_dir": str(sw.out),
    }
    report.setdefault("metrics", {})["sweep_wall_s"] = round(wall, 2)
    report.setdefault("interrupted", False)
    expectations = getattr(sw.cfg, "expect", ())
    if expectations:
        report["expect"] = trial_expectations(expectations, [done[i] for i in sw.ids])
    return _write_report(sw.out, report)


def trial_expectations(expectations: tuple, records: list[dict]) -> dict:
    """The sweep report's ``expect`` block: each trial's metrics checked against the
    scenario's expectations (:mod:`sim.experiments.expect`), and whether every trial met them."""
    trials = []
    for rec in records:
        block = check(expectations, rec["result"].get("metrics", {}))
        trials.append({"id": rec["id"], "passed": block["passed"], "failed": failures(block)})
    return {"passed": all(t["passed"] for t in trials), "expectations": [str(e) for e in expectations], "trials": trials}


def run_experiment(
    exp: Experiment,
    cfg: Any,
    out_dir: str | Path,
    *,
    trials: int | None = None,
    seed: int | None = None,
    engine: str = "local",
    workers: int | None = None,
    address: str | None = None,
    resume: bool | str = False,
    progress: bool = True,
    source: tuple | None = None,
    scenario: str | None = None,
    overrides: list[str] | None = None,
    resume_hint: str | None = None,
) -> dict:
    """Run (or finish) a sweep of ``exp`` over ``cfg``; returns the report.

    ``resume``: True finishes the sweep in ``out_dir`` (error if it is another sweep);
    False refuses a directory that already holds finished trials; "auto" resumes when
    ``sweep.json`` matches and starts afresh otherwise.
    """
    n = _check_args(cfg, engine, trials, workers, address)
    workers = workers or os.cpu_count() or 1
    seed = int(getattr(cfg, "seed", 0)) if seed is None else int(seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    specs = _trial_specs(exp, cfg, n, seed)
    meta = {
        "version": SWEEP_VERSION,
        "kind": exp.kind,
        "scenario": scenario or getattr(cfg, "name", ""),
        "overrides": list(overrides or []),
        "trials": n,
        "seed": seed,
        "config_hash": config_hash(cfg),
        "trial_ids": len(specs),
    }
    hint = resume_hint or f"depthnav sweep {meta['scenario']} --out {out} --resume" + (f" --trials {n}" if trials is not None else "")
    sw = _Sweep(exp, cfg, out, specs, meta, engine, workers, address, source if source is not None else ("config", cfg), hint)
    done = _finished_trials(sw, resume)
    pending = [s for s in specs if s["id"] not in done]
    resumed = len(done)
    errors, wall, interrupted = _run_pending(sw, pending, done, progress)
    if interrupted:
        return _interrupted_report(sw, wall)
    if errors:
        raise SweepError(f"{len(errors)} of {len(specs)} trials failed (first: {errors[0][0]}: {errors[0][1]}); the {len(done)} finished are kept in {sw.trials_path}; fix and resume with: {hint}")
    return _final_report(sw, done, len(pending), resumed, wall)


def run_sweep(
    scenario_path: str | Path,
    overrides: list[str] | None,
    out_dir: str | Path | None,
    trials: int | None = None,
    engine: str = "local",
    workers: int | None = None,
    address: str | None = None,
    resume: bool = False,
    progress: bool = True,
    seed: int | None = None,
) -> dict:
    """``depthnav sweep``: load the scenario and run its sweep (see the module docstring)."""
    overrides = list(overrides or [])
    exp, cfg = load_experiment(scenario_path, overrides)
    from autonomy.common.files import output_path

    out = output_path(Path(out_dir) if out_dir else Path("runs") / f"{cfg.name}-sweep", "--out", directory=True)
    path = str(Path(scenario_path).resolve())
    sets = "".join(f" --set {o}" for o in overrides)
    hint = f"depthnav sweep {scenario_path} --out {out} --resume" + (f" --trials {trials}" if trials is not None else "") + (f" --seed {seed}" if seed is not None else "") + sets + (f" --engine {engine}" if engine != "local" else "")
    return run_experiment(
        exp, cfg, out, trials=trials, seed=seed, engine=engine, workers=workers, address=address,
        resume=resume, progress=progress, source=("path", path, overrides), scenario=str(scenario_path),
        overrides=overrides, resume_hint=hint,
    )
