"""A trivially cheap experiment kind for the sweep engine's tests (``tiny_test``).

Registered at run time (``sim.experiments.kinds.KINDS["tiny_test"] = "tests.sim.sweep_kind"``);
the engine passes the module name to its workers, which register it too. Each trial
draws a number from its seed, optionally sleeps, and leaves a marker file per execution
so tests can count how often each trial ran.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.experiments.kinds import Experiment

KIND = "tiny_test"
MODULE = "tests.sim.sweep_kind"


@dataclass(frozen=True)
class TinyConfig:
    name: str = "tiny"
    description: str = ""
    seed: int = 0
    sleep_s: float = 0.0
    marker_dir: str = ""
    fail_id: str = ""
    base_dir: str = ""


def trials(cfg: TinyConfig, n: int, seed: int) -> list[dict]:
    seeds = np.random.SeedSequence(seed).generate_state(n, dtype=np.uint32)
    return [{"id": f"t-{i:04d}", "seed": int(s)} for i, s in enumerate(seeds)]


def trial(cfg: TinyConfig, spec: dict) -> dict:
    if cfg.marker_dir:
        Path(cfg.marker_dir).mkdir(parents=True, exist_ok=True)
        (Path(cfg.marker_dir) / f"{spec['id']}.{os.getpid()}.{time.time_ns()}").touch()
    if spec["id"] == cfg.fail_id:
        raise ValueError(f"trial {spec['id']} fails on purpose")
    if cfg.sleep_s:
        time.sleep(cfg.sleep_s)
    return {"value": float(np.random.default_rng(spec["seed"]).random()), "seed": spec["seed"]}


def summarize(cfg: TinyConfig, results: list[dict], out_dir: Path) -> dict:
    report = {"scenario": cfg.name, "interrupted": False, "metrics": {"trials": len(results), "mean": float(np.mean([r["value"] for r in results]))}}
    Path(out_dir, "report.json").write_text(json.dumps(report) + "\n")
    return report


def run(cfg: TinyConfig, out_dir, *, seed=None, rrd=None, spawn=False, progress=None) -> dict:
    raise NotImplementedError


EXPERIMENTS = {KIND: Experiment(KIND, TinyConfig, run, trials, trial, summarize)}


def register() -> None:
    from sim.experiments.kinds import KINDS

    KINDS[KIND] = MODULE
