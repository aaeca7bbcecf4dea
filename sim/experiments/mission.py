"""The ``mission`` experiment kind: waypoint runs and long-run trials (:mod:`sim.experiments.runner`).

One trial of a sweep is one whole run with its own seed (people, furniture, waypoints,
odometry and sensor noise all drawn from it), written without figures or recordings;
the summary gives each metric's mean, min and max over trials and the totals the
paper's long-run trial counts (distance, resets, collisions).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from sim.experiments.kinds import Experiment
from sim.experiments.report_file import write_json
from sim.scenario import Scenario


def run(
    cfg: Scenario, out_dir: str | Path, *, seed: int | None = None, rrd=None, spawn: bool = False, progress=None, bag=None, bag_depth: str = "32FC1",
) -> dict:
    from sim.experiments.runner import run_scenario

    return run_scenario(cfg, out_dir, seed=seed, rrd=rrd, spawn=spawn, progress=progress, bag=bag, bag_depth=bag_depth)


def trials(cfg: Scenario, n: int, seed: int) -> list[dict]:
    """``n`` trials with seeds spawned from the sweep's seed. A map without a navigation
    graph gets its graph made here, once, so the workers read it from the cache instead
    of each making it."""
    if cfg.map.vectormap and not cfg.map.navgraph:
        from sim.experiments.site import load_building

        load_building(cfg)
    seeds = np.random.SeedSequence(seed).generate_state(n, dtype=np.uint32)
    return [{"id": f"trial-{i:04d}", "seed": int(s)} for i, s in enumerate(seeds)]


def quiet_report(cfg: Scenario, seed: int, what: str) -> dict:
    """One run of ``cfg`` headless, without figures, progress or checkpoints, in a
    directory that goes with it; its report. A crash is a RuntimeError naming ``what``
    and the error; an interrupted run is a KeyboardInterrupt."""
    import dataclasses

    from sim.experiments.kinds import RunCrashed
    from sim.experiments.runner import run_scenario

    quiet = dataclasses.replace(cfg, report=dataclasses.replace(cfg.report, figures=False, progress=False, checkpoint_s=0.0))
    with tempfile.TemporaryDirectory(prefix="depthnav-trial-") as d:
        try:
            report = run_scenario(quiet, d, seed=seed, progress=False)
        except RunCrashed as exc:
            # The trial's directory goes with it: the sweep gets where and which error.
            raise RuntimeError(f"{what}: {exc.what}") from None
    if report["interrupted"]:
        raise KeyboardInterrupt
    return report


def trial(cfg: Scenario, spec: dict) -> dict:
    """One run, headless and quiet; its metrics (plus the seed) as the result."""
    report = quiet_report(cfg, int(spec["seed"]), f"seed {spec['seed']}")
    return {"seed": report["seed"], "metrics": report["metrics"], "timing_ms": report["timing_ms"], "events": report["events"]}


def summarize(cfg: Scenario, results: list[dict], out_dir: Path) -> dict:
    from sim.experiments.report import PAPER_FIGURES

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    keys = sorted({k for r in results for k, v in r["metrics"].items() if isinstance(v, (int, float))})
    stats: dict[str, Any] = {}
    for k in keys:
        v = np.array([r["metrics"][k] for r in results if k in r["metrics"]], dtype=np.float64)
        stats[k] = {"mean": round(float(v.mean()), 4), "min": round(float(v.min()), 4), "max": round(float(v.max()), 4)}
    totals = {
        k: round(float(sum(r["metrics"].get(k, 0) for r in results)), 4)
        for k in ("distance_m", "duration_s", "collisions", "resets", "waypoints_reached", "waypoints_failed")
    }
    report = {
        "scenario": cfg.name,
        "kind": "mission",
        "trials": len(results),
        "interrupted": False,
        "metrics": {"trials": len(results), **{f"total_{k}": v for k, v in totals.items()}},
        "per_metric": stats,
        "paper": PAPER_FIGURES.get(cfg.name, {}),
        "seeds": [r["seed"] for r in results],
    }
    write_json(out_dir / "report.json", report)
    return report


EXPERIMENTS = {"mission": Experiment("mission", Scenario, run, trials, trial, summarize)}
