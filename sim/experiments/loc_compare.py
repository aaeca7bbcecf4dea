"""The ``localization_comparison`` experiment kind: BV2012, VI-A and Figs. 5-7.

One drive (:mod:`sim.experiments.drives`) is recorded once; each trial replays it offline
with one approach and one seed (:mod:`sim.experiments.loc_replay`: the configuration, the
shared context and the replay itself). This module makes the trials, and from all
replays the report and Figs. 5-7.

Trials: ``--trials N`` (and ``replays`` in the scenario) is the number of replays *per
approach*, so a sweep holds ``N x len(approaches)`` trials with ids ``<approach>-<i>``.
Replay ``i`` has the same seed for every approach, so the approaches see the same
odometry noise (common random numbers); the FSPF and KS pixel samples are seeded per
replay and frame.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from sim.config import to_dict
from sim.experiments.kinds import Experiment
from sim.experiments.loc_replay import (
    APPROACHES,
    HIST_MAX_M,
    HIST_STEP_M,
    Context,
    LocComparisonConfig,
    hist_edges,
    prepare,
    replay,
)
from sim.experiments.report_file import config_json, write_json

#: BV2012, VI-A: failure rates and CPU loads of the four approaches.
PAPER = {
    "fspf": {"failure_rate": 0.02, "cpu_load": 0.163},
    "kr": {"failure_rate": 0.82, "cpu_load": 0.0001},
    "ks": {"failure_rate": 0.62, "cpu_load": 0.036},
    "kc": {"failure_rate": 0.61, "cpu_load": 0.566},
}

LABELS = {"fspf": "FSPF", "kr": "KR", "ks": "KS", "kc": "KC", "mcl": "MCL (FSPF points)"}
#: Fig. 5's colours: green KR, red KS, blue KC, black FSPF.
COLORS = {"fspf": "black", "kr": "#2ca02c", "ks": "#d62728", "kc": "#1f77b4", "mcl": "#ff7f0e"}


# --------------------------------------------------------------------------- the kind


def trials(cfg: LocComparisonConfig, n: int, seed: int) -> list[dict]:
    """``n`` replays per approach; replay i has the same seed for every approach."""
    seeds = np.random.SeedSequence(int(seed)).generate_state(n, dtype=np.uint32)
    return [
        {"id": f"{a}-{i:04d}", "approach": a, "replay": i, "seed": int(s)}
        for a in cfg.approaches
        for i, s in enumerate(seeds)
    ]


def trial(cfg: LocComparisonConfig, spec: dict) -> dict:
    """One replay (the log is recorded first if no process has done it yet)."""
    if spec.get("approach") not in APPROACHES:
        raise InputError(f"trial {spec.get('id')!r}: unknown approach {spec.get('approach')!r}")
    out = replay(prepare(cfg), cfg, spec["approach"], int(spec["seed"]))
    out["replay"] = int(spec.get("replay", 0))
    return out


def _quantile_from_hist(counts: np.ndarray, q: float) -> float:
    c = np.cumsum(counts)
    if not len(c) or c[-1] == 0:
        return float("nan")
    target = q * c[-1]
    i = int(np.searchsorted(c, target))
    prev = c[i - 1] if i > 0 else 0
    frac = (target - prev) / max(counts[i], 1)
    return float((i + frac) * HIST_STEP_M)


def summarize(cfg: LocComparisonConfig, results: list[dict], out_dir: Path) -> dict:
    """report.json and Figs. 5-7 from all replays."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    ctx = prepare(cfg)
    log = ctx.log
    order = [a for a in cfg.approaches if any(r["approach"] == a for r in results)]
    order += sorted({r["approach"] for r in results} - set(order))
    nb = len(hist_edges()) - 1
    per: dict[str, dict] = {}
    for a in order:
        rs = [r for r in results if r["approach"] == a]
        hist = np.zeros(nb, dtype=np.int64)
        for r in rs:
            h = np.asarray(r["error_hist"], dtype=np.int64)
            hist[: len(h)] += h
        frames = sum(r["frames"] for r in rs)
        ok = [r for r in rs if not r["failed"]]
        tm = [r["timing"] for r in rs]
        per[a] = {
            "trials": len(rs),
            "failures": sum(r["failed"] for r in rs),
            "failure_rate": round(sum(r["failed"] for r in rs) / len(rs), 4),
            "cpu_load": round(float(np.mean([t["cpu_load"] for t in tm])), 6),
            "cpu_load_with_localization": round(float(np.mean([t["cpu_load_with_localization"] for t in tm])), 6),
            "mean_error_m": round(sum(r["error_sum_m"] for r in rs) / max(frames, 1), 4),
            "median_error_m": round(_quantile_from_hist(hist, 0.5), 4),
            "p95_error_m": round(_quantile_from_hist(hist, 0.95), 4),
            "mean_error_successful_m": round(sum(r["error_sum_m"] for r in ok) / max(sum(r["frames"] for r in ok), 1), 4) if ok else None,
            "processing_ms_per_frame": round(1e3 * float(np.mean([t["processing_s"] for t in tm])) / max(log.n_frames - 1, 1), 4),
            "localization_ms_per_frame": round(1e3 * float(np.mean([t["localization_s"] for t in tm])) / max(log.n_frames - 1, 1), 4),
            "replay_wall_s_mean": round(float(np.mean([t["replay_wall_s"] for t in tm])), 3),
            "paper": PAPER.get(a, {}),
            "_hist": hist,
        }
    figures = _figures(cfg, ctx, results, per, order, out_dir)
    for a in order:
        per[a].pop("_hist")
    metrics: dict[str, Any] = {"trials": len(results), "log_frames": log.n_frames, "log_duration_s": round(log.duration_s, 3)}
    for a in order:
        for k in ("failure_rate", "cpu_load", "mean_error_m", "median_error_m"):
            metrics[f"{a}_{k}"] = per[a][k]
    report = {
        "scenario": cfg.name,
        "kind": "localization_comparison",
        "trials": len(results),
        "replays_per_approach": {a: per[a]["trials"] for a in order},
        "interrupted": False,
        "metrics": metrics,
        "approaches": per,
        "paper": PAPER,
        "paper_notes": "BV2012, VI-A: failure 2% / 82% / 62% / 61% and CPU 16.3% / 0.01% / 3.6% / 56.6% for FSPF / KR / KS / KC; the paper's CPU load counts processing the depth images (FSPF or scan simulation), single threaded on a Core i7 950",
        "log": {
            "path": str(log.path),
            "frames": log.n_frames,
            "duration_s": round(log.duration_s, 3),
            "distance_m": round(log.distance_m, 2),
            "collisions": log.meta.get("collisions"),
            "route_completed": log.meta.get("completed"),
        },
        "figures": figures,
        "config": {k: v for k, v in config_json(to_dict(cfg)).items() if k != "base_dir"},
    }
    write_json(out_dir / "report.json", report)
    return report




def _figures(cfg, ctx: Context, results: list[dict], per: dict, order: list[str], out_dir: Path) -> dict[str, str]:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    log = ctx.log
    files = {}
    # Fig. 5: traces of all successful replays over the map.
    fig = Figure(figsize=(9, 7), dpi=130)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    segs = ctx.query.vm.segments
    ax.add_collection(LineCollection(segs.reshape(-1, 2, 2), colors="0.55", linewidths=0.7))
    for a in order:
        first = True
        for r in results:
            if r["approach"] == a and not r["failed"] and r["trace"]:
                tr = np.asarray(r["trace"])
                ax.plot(tr[:, 0], tr[:, 1], color=COLORS.get(a, "gray"), lw=0.5, alpha=0.35, label=f"{LABELS.get(a, a)} ({per[a]['trials'] - per[a]['failures']} successful)" if first else None)
                first = False
    ax.plot(log.poses[:, 0], log.poses[:, 1], color="#9467bd", lw=1.0, ls="--", label="ground truth")
    if log.people.size:
        pp = log.people[:: max(1, log.n_frames // 200)].reshape(-1, 3)
        ax.scatter(pp[:, 0], pp[:, 1], s=2, color="#e377c2", alpha=0.4, label="people (over time)")
    lo = log.poses[:, :2].min(0) - 4.0
    hi = log.poses[:, :2].max(0) + 4.0
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Fig. 5: estimates of all successful replays")
    ax.legend(loc="best", fontsize=7)
    fig.savefig(out_dir / "fig5_traces.png")
    files["traces"] = "fig5_traces.png"

    # Fig. 6: cumulative failure rate against elapsed time.
    fig = Figure(figsize=(7, 4.5), dpi=130)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    T = log.duration_s
    for a in order:
        rs = [r for r in results if r["approach"] == a]
        ts = np.sort([r["failure_t_s"] for r in rs if r["failed"]])
        x = np.concatenate([[0.0], ts, [T]])
        y = np.concatenate([[0.0], np.arange(1, len(ts) + 1) / len(rs), [len(ts) / len(rs)]])
        ax.step(x, 100 * y, where="post", color=COLORS.get(a, "gray"), label=f"{LABELS.get(a, a)} ({100 * per[a]['failure_rate']:.0f}%; paper {100 * PAPER[a]['failure_rate']:.0f}%)" if a in PAPER else LABELS.get(a, a))
    ax.set_xlabel("elapsed time [s]")
    ax.set_ylabel("cumulative failure rate [%]")
    ax.set_xlim(0, T)
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Fig. 6: cumulative failure rate")
    fig.savefig(out_dir / "fig6_failure_rate.png")
    files["failure_rate"] = "fig6_failure_rate.png"

    # Fig. 7: cumulative histogram of the error (fraction of time with error < x).
    fig = Figure(figsize=(7, 4.5), dpi=130)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    edges = hist_edges()[1:-1]
    for a in order:
        h = per[a]["_hist"]
        c = np.cumsum(h)[: len(edges)] / max(h.sum(), 1)
        ax.plot(edges, c, color=COLORS.get(a, "gray"), label=LABELS.get(a, a))
    ax.set_xscale("log")
    ax.set_xlim(0.01, HIST_MAX_M)
    ax.set_ylim(0, 1.01)
    ax.set_xlabel("localization error x [m]")
    ax.set_ylabel("fraction of time with error < x")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title("Fig. 7: cumulative histogram of the error")
    fig.savefig(out_dir / "fig7_error_cdf.png")
    files["error_cdf"] = "fig7_error_cdf.png"
    return files


def run(cfg: LocComparisonConfig, out_dir: str | Path, *, seed: int | None = None, rrd=None, spawn: bool = False, progress=None) -> dict:
    """``depthnav run``: ``cfg.replays`` replays per approach on this machine's cores (the
    sweep engine's local engine; an interrupted run resumes when run again into the same
    directory)."""
    from sim.experiments.sweep import run_experiment

    if rrd or spawn:
        raise InputError("localization_comparison: --rrd/--spawn are not supported (replays render nothing)")
    show = progress if progress is not None else sys.stderr.isatty()
    return run_experiment(
        EXPERIMENTS["localization_comparison"], cfg, out_dir, trials=cfg.replays,
        seed=cfg.seed if seed is None else int(seed), engine="local", workers=cfg.workers or None,
        resume="auto", progress=show, resume_hint=f"run the same `depthnav run` command again with --out {out_dir}",
    )


EXPERIMENTS = {
    "localization_comparison": Experiment("localization_comparison", LocComparisonConfig, run, trials, trial, summarize),
}
