"""One invocation, one sweep trial and one sweep summary of any mapping experiment: each
experiment hands in its ``measure`` (:data:`Measure`) and its paper's figures.

Every run writes ``report.json`` with ``metrics`` (ours) and ``paper`` (PlaneMap's
figures under the same names). A run stopped by Ctrl-C or by an error keeps the metrics
of the frames it finished; an error adds an ``error`` block and the traceback in
``crash.txt``, and the run raises :class:`sim.experiments.kinds.RunCrashed`. A sweep
trial is one seeded noise draw of the whole experiment; the summary gives each metric's
mean, std, min and max over trials.
"""

from __future__ import annotations

import functools
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from sim.config import to_dict
from sim.experiments.kinds import Experiment, crash_block, stopped, write_crash
from sim.experiments.mapping.common import MappingExperiment, Stop, finite, seeds
from sim.experiments.report_file import write_json

REPORT_VERSION = 1

#: ``measure(cfg, seed, progress, out_dir, rec) -> (metrics, details, stop, files)``: one
#: whole experiment; ``out_dir`` (None: write nothing) gets its files, ``rec``
#: (:class:`sim.viz.recording.Recorder` or None) its recording.
Measure = Callable[[Any, int, bool | None, Path | None, Any], tuple[dict, dict, Stop, list[str]]]


def _write_report(out_dir: Path, report: dict) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "report.json", report)


def _report(
    kind: str, paper: dict[str, float], cfg: MappingExperiment, seed: int, metrics: dict, details: dict, interrupted: bool,
    files: list[str], wall_s: float,
) -> dict:
    return {
        "version": REPORT_VERSION,
        "scenario": cfg.name,
        "kind": kind,
        "seed": seed,
        "interrupted": interrupted,
        "metrics": {k: finite(v) for k, v in metrics.items()},
        "paper": paper,
        "details": details,
        "files": files,
        "wall_time_s": round(wall_s, 2),
        "machine": f"Python {platform.python_version()}, {os.cpu_count()} cores, {platform.processor() or platform.machine()}",
        "config": to_dict(cfg),
    }


def run_experiment(
    kind: str,
    paper: dict[str, float],
    measure: Measure,
    cfg: MappingExperiment,
    out_dir: str | Path,
    *,
    seed: int | None = None,
    rrd: str | Path | None = None,
    spawn: bool = False,
    progress: bool | None = None,
) -> dict:
    """Measure ``cfg`` once and write ``out_dir/report.json`` (and, with ``rrd`` or
    ``spawn``, a rerun recording); the report."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create the output directory: {exc.strerror or exc}") from None
    seed = cfg.seed if seed is None else int(seed)
    t0 = time.perf_counter()
    rec = None
    if rrd or spawn:
        # rerun is imported only by a run that records.
        from sim.viz.recording import Recorder

        rate_hz = cfg.sensor.kinect().rate_hz
        every = max(1, round(rate_hz / getattr(cfg, "map_rate_hz", rate_hz)))
        rec = Recorder(rrd, spawn=spawn, every=every, recording_id=f"{cfg.name}-{seed}")
    try:
        metrics, details, stop, files = measure(cfg, seed, progress, out, rec)
    except Exception as exc:  # the summary of what the loop left failed: the error is kept
        metrics, details, stop, files = {}, {}, Stop(error=exc), []
    finally:
        if rec is not None:
            rec.close()
    if rrd:
        rp = Path(rrd)
        files.append(rp.name if rp.parent.resolve() == out.resolve() else str(rp))
    report = _report(kind, paper, cfg, seed, metrics, details, stop.early, files, time.perf_counter() - t0)
    err = stop.error
    if err is not None:
        report["error"] = crash_block(err)
        write_crash(out, err)
    _write_report(out, report)
    if err is not None:
        raise stopped(err, "the run stopped", out / "report.json") from None
    return report


def trials(cfg: MappingExperiment, n: int, seed: int) -> list[dict]:
    """``n`` trials, each one seeded noise draw of the whole experiment."""
    return [{"id": f"trial-{i:04d}", "seed": s} for i, s in enumerate(seeds(seed, n))]


def run_trial(measure: Measure, cfg: MappingExperiment, spec: dict) -> dict:
    """One sweep trial (no files): its seed and metrics; an error or Ctrl-C is raised."""
    s = int(spec["seed"])
    metrics, _, stop, _ = measure(cfg, s, False, None, None)
    if stop.error is not None:
        raise stop.error
    if stop.interrupted:
        raise KeyboardInterrupt
    return {"seed": s, "metrics": {k: finite(v) for k, v in metrics.items()}}


def summarize(kind: str, paper: dict[str, float], cfg: MappingExperiment, results: list[dict], out_dir: Path) -> dict:
    """Mean, std, min and max of every metric over the trials' ``results``; writes report.json."""
    out = Path(out_dir)
    keys = sorted({k for r in results for k in r["metrics"]})
    per: dict[str, dict[str, float | None]] = {}
    metrics: dict[str, float | None] = {"trials": len(results)}
    for k in keys:
        v = np.array([r["metrics"][k] for r in results if r["metrics"].get(k) is not None], dtype=np.float64)
        if not len(v):
            per[k] = {"mean": None, "std": None, "min": None, "max": None, "n": 0}
            metrics[k] = None
            continue
        per[k] = {"mean": finite(v.mean()), "std": finite(v.std()), "min": finite(v.min()), "max": finite(v.max()), "n": len(v)}
        metrics[k] = finite(v.mean())
    report = {
        "version": REPORT_VERSION,
        "scenario": cfg.name,
        "kind": kind,
        "trials": len(results),
        "interrupted": False,
        "metrics": metrics,
        "per_metric": per,
        "paper": paper,
        "seeds": [r["seed"] for r in results],
        "config": to_dict(cfg),
    }
    _write_report(out, report)
    return report


def mapping_experiment(
    kind: str, paper: dict[str, float], config_type: type, measure: Measure, trial: Callable[[Any, dict], dict] | None = None
) -> Experiment:
    """The :class:`Experiment` of a mapping kind: its run, trials and summary all go
    through this driver with the kind's ``measure`` (``trial``: the kind's own, if it
    differs from :func:`run_trial`)."""
    return Experiment(
        kind,
        config_type,
        functools.partial(run_experiment, kind, paper, measure),
        trials,
        trial if trial is not None else functools.partial(run_trial, measure),
        functools.partial(summarize, kind, paper),
    )
