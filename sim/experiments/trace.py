"""Per-frame trace of a time window of a run (``report.trace_s``): ``trace.jsonl``.

A long run's report says that something happened at 3,971 s; the trace says how, frame
by frame: the true pose beside the belief and the odometry, the error, the health
monitor's averages and verdict, the localizer's spread and its correction beyond the
odometry, what CGR's update did (points matched, samples shared, held or dropped),
the navigator's state and command, and what the stack made of the frame. A
run is seeded and the closed loop deterministic, so the same seed with a window round
that moment (and ``mission.max_duration_s`` at its end, to stop there) replays it:

    depthnav run scenarios/long_run.toml --seed 5226 --out runs/trace_5226 \\
        --set 'report.trace_s=[3955,3990]' --set mission.max_duration_s=3990
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from autonomy.common.geometry import wrap_angle
from autonomy.navigation.config import NavCommand
from autonomy.stack import StackOutput

__all__ = ["TRACE_FILE", "in_window", "trace_record", "write_trace"]

TRACE_FILE = "trace.jsonl"


def in_window(window: tuple[float, ...], t: float) -> bool:
    """Whether time ``t`` lies in the trace window (from, to); never without one."""
    return len(window) == 2 and window[0] <= t <= window[1]


def _num(v: float, nd: int = 4) -> float | None:
    """A JSON number (None for NaN or infinite: JSON has neither)."""
    v = float(v)
    return round(v, nd) if math.isfinite(v) else None


def _vec(a, nd: int = 4) -> list[float | None]:
    return [_num(v, nd) for v in np.asarray(a, dtype=np.float64).ravel()]


def trace_record(t: float, truth: np.ndarray, out: StackOutput, nav: NavCommand) -> str:
    """One frame's record as a JSON line: ``truth`` the true pose after the frame, ``out``
    the stack's output on it, ``nav`` the command the robot was driven by into it."""
    est = np.asarray(out.estimate, dtype=np.float64)
    per = out.perception
    rec: dict = {
        "t": _num(t),
        "truth": _vec(truth),
        "estimate": _vec(est),
        "odometry": _vec(out.odometry),
        "error_m": _num(math.hypot(est[0] - truth[0], est[1] - truth[1])),
        "heading_error_deg": _num(math.degrees(wrap_angle(est[2] - truth[2])), 3),
        "spread": _vec(out.spread),
        "correction": None if out.correction is None else _vec(out.correction),
        "health": out.health_state,
        "frame_fault": out.frame_fault,
        "points_2d": int(len(per.points_2d)),
        "obstacles": int(len(per.obstacles)),
        "nav_state": nav.state,
        "command": _vec(nav.velocity),
        "desired_deg": _num(math.degrees(nav.desired_rad), 2),
        "theta_star_deg": _num(math.degrees(nav.theta_star_rad), 2),
    }
    if out.cgr_stats is not None:
        rec["cgr"] = dataclasses.asdict(out.cgr_stats)
    h = out.health_sample
    if h is not None:
        rec["monitor"] = {
            "reason": h.reason,
            "explained": _num(h.explained),
            "explained_fast": _num(h.explained_fast),
            "explained_slow": _num(h.explained_slow),
            "through_fast": _num(h.through_fast),
            "jump_m": _num(h.jump_m),
            "view_agree": _num(h.view_agree),
            "missing_fast": _num(h.missing_fast),
        }
    return json.dumps(rec)


def write_trace(path: Path, lines: list[str]) -> None:
    """The records, one JSON line each."""
    with open(path, "w", encoding="utf-8") as f:
        for line in lines:
            f.write(line + "\n")
