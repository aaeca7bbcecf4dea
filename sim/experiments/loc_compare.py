"""The ``localization_comparison`` experiment kind: BV2012, VI-A and Figs. 5-7.

One drive (:mod:`sim.experiments.drives`) is recorded once; each trial replays it offline with one
approach and one seed: per frame, the observation is made from the stored depth frame
(FSPF's plane-filtered points, or a laser scan simulated by KR / KS / KC,
:mod:`autonomy.localization.scans`), CGR predicts with the recorded odometry plus 20% multiplicative
noise and updates with the observation, and the estimate is compared with the recorded
truth. Nothing is rendered again. A replay fails if its error ever reaches 1 m.

Trials: ``--trials N`` (and ``replays`` in the scenario) is the number of replays *per
approach*, so a sweep holds ``N x len(approaches)`` trials with ids ``<approach>-<i>``.
Replay ``i`` has the same seed for every approach, so the approaches see the same
odometry noise (common random numbers); the FSPF and KS pixel samples are seeded per
replay and frame. KR and KC are deterministic per frame: their scans are computed once
per frame (timed, for the CPU load) and cached beside the log.

CPU load, as the paper: the time spent turning depth frames into observations (FSPF,
or scan simulation and down-projection) divided by the log's duration. We also report
the load with the CGR update included. Times are the thread's CPU time
(``time.thread_time``), so other processes on a shared machine do not inflate them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write
from autonomy.localization.cgr import CGRConfig, CGRLocalizer
from autonomy.localization.observation import ObservationConfig
from autonomy.localization.scans import (
    ScanConfig,
    complete_scan,
    drop_floor,
    raster_scan,
    sampling_scan,
    scan_points,
)
from autonomy.maps.raycast import SceneQuery, VisibilityGridConfig, load_or_build
from autonomy.perception.camera import DepthCamera
from autonomy.perception.fspf import FSPFConfig, project_to_floor
from autonomy.stack import LOCALIZATION_GRID, LocalizationConfig, RobotStack, StackConfig
from sim.config import to_dict
from sim.experiments.drives import DriveLog, RecordingConfig, ensure_log, load_log
from sim.experiments.kinds import Experiment
from sim.experiments.report_file import config_json, write_json
from sim.simulator.robot import OdometryConfig

#: Approaches: the paper's four, and plain MCL on FSPF's points (CGR without refinement)
#: as an ablation.
APPROACHES = ("fspf", "kr", "ks", "kc", "mcl")

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

#: Error histogram bins (Fig. 7): 1 cm up to 5 m, then everything beyond.
HIST_STEP_M = 0.01
HIST_MAX_M = 5.0


@dataclass(frozen=True)
class LocComparisonConfig:
    """A localization comparison (scenarios/localization_comparison.toml)."""

    name: str
    """Short name used in reports (and in the cached log's file name)."""
    recording: RecordingConfig
    """The drive recorded once and replayed."""
    description: str = ""
    """One line shown by ``depthnav scenarios``."""
    seed: int = 0
    """Master seed of the replays (each replay's seed is spawned from it)."""
    replays: int = 100
    """Replays per approach (VI-A: 100)."""
    approaches: tuple[str, ...] = ("fspf", "kr", "ks", "kc")
    """Approaches to compare: fspf, kr, ks, kc (the paper's), mcl (ablation)."""
    failure_error_m: float = 1.0
    """A replay fails if its error is at least this at any timestep (VI-A: 1 m)."""
    cache_dir: str = ""
    """Where recorded logs are cached (relative to the scenario file); "" = $DEPTHNAV_CACHE/logs
    or ~/.cache/depthnav/logs."""
    workers: int = 0
    """Processes for ``depthnav run``; 0 = one per CPU core."""
    trace_hz: float = 5.0
    """Rate at which each replay's estimate is kept for Fig. 5."""
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    """Odometry noise added in each replay (VI-A: 20%)."""
    fspf: FSPFConfig = field(default_factory=FSPFConfig)
    """FSPF (Table I)."""
    scans: ScanConfig = field(default_factory=ScanConfig)
    """Simulated laser scans (180 degrees at 0.35 degrees) and the floor test for all."""
    cgr: CGRConfig = field(default_factory=CGRConfig)
    """CGR, the same for every approach."""
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    """Point-cloud observation model (FSPF, MCL)."""
    laser_observation: ObservationConfig = field(default_factory=ObservationConfig)
    """Laser observation model (KR, KS, KC)."""
    grid: VisibilityGridConfig = LOCALIZATION_GRID
    """Visibility grid of the analytic ray cast."""
    base_dir: str = ""
    """Directory relative paths resolve against (set by the loader)."""

    def __post_init__(self) -> None:
        if not (isinstance(self.replays, int) and self.replays >= 1):
            raise InputError(f"replays: expected an integer >= 1, got {self.replays!r}")
        if not self.approaches:
            raise InputError("approaches: expected at least one of " + ", ".join(APPROACHES))
        for a in self.approaches:
            if a not in APPROACHES:
                raise InputError(f"approaches: unknown approach {a!r} (expected some of: {', '.join(APPROACHES)})")
        if len(set(self.approaches)) != len(self.approaches):
            raise InputError("approaches: each approach at most once")
        if not self.failure_error_m > 0:
            raise InputError("failure_error_m: expected a positive number")
        if self.workers < 0:
            raise InputError("workers: expected an integer >= 0 (0 = one per core)")
        if not self.trace_hz > 0:
            raise InputError("trace_hz: expected a positive number")

    def cache_path(self) -> Path | None:
        if not self.cache_dir:
            return None
        p = Path(self.cache_dir)
        return p if p.is_absolute() else Path(self.base_dir or ".") / p


# --------------------------------------------------------------------------- the context


@dataclass
class Context:
    """What every replay of one comparison shares in a process: log, map, cached scans."""

    log: DriveLog
    query: SceneQuery
    scans: dict[str, np.ndarray]
    """kr / kc: (N, n_beams) float32 ranges, computed once per frame."""
    scan_s: dict[str, np.ndarray]
    """kr / kc: (N,) seconds it took to make each frame's scan."""


_CONTEXTS: dict[str, Context] = {}


def _context_key(cfg: LocComparisonConfig) -> str:
    payload = json.dumps({"rec": cfg.recording.key(), "scans": to_dict(cfg.scans), "grid": to_dict(cfg.grid), "cache": str(cfg.cache_path())}, sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


def _scans_path(log_path: Path, scfg: ScanConfig) -> Path:
    h = hashlib.sha256(json.dumps(to_dict(scfg), sort_keys=True).encode()).hexdigest()[:12]
    return log_path.with_name(log_path.name.removesuffix(".log.npz") + f".scans-{h}.npz")


def _deterministic_scans(log: DriveLog, scfg: ScanConfig, path: Path, progress: bool) -> tuple[dict, dict]:
    """KR and KC scans of every frame, computed once (timed) and cached beside the log."""
    from sim.experiments.drives import _locked

    def read() -> tuple[dict, dict] | None:
        try:
            with np.load(path) as z:
                if z["kr"].shape[0] != log.n_frames:
                    return None
                return {a: z[a] for a in ("kr", "kc")}, {a: z[f"{a}_s"] for a in ("kr", "kc")}
        except (OSError, KeyError, ValueError):
            return None

    got = read()
    if got is not None:
        return got
    with _locked(path):
        got = read()
        if got is not None:
            return got
        n = log.n_frames
        fns = {"kr": raster_scan, "kc": complete_scan}
        out = {a: np.zeros((n, scfg.n_beams), np.float32) for a in fns}
        secs = {a: np.zeros(n) for a in fns}
        for fn in fns.values():  # warm the JIT outside the timing
            fn(np.asarray(log.depth_mm[0]), log.intrinsics, log.mount, scfg)
        it = range(n)
        if progress:
            from tqdm import tqdm

            it = tqdm(it, desc="KR/KC scans of every frame", unit="frame", leave=False, file=sys.stderr)
        for k in it:
            d = np.asarray(log.depth_mm[k])
            for a, fn in fns.items():
                t0 = time.thread_time()
                out[a][k] = fn(d, log.intrinsics, log.mount, scfg)
                secs[a][k] = time.thread_time() - t0
        atomic_write(path, lambda f: np.savez(f, kr=out["kr"], kc=out["kc"], kr_s=secs["kr"], kc_s=secs["kc"]))
    return out, secs


def prepare(cfg: LocComparisonConfig, progress: bool = False) -> Context:
    """Record (or find) the log, its cached KR/KC scans and the map's ray-cast grid; cached
    per process. Sweeps call this in the parent before dispatching trials."""
    key = _context_key(cfg)
    if key in _CONTEXTS:
        return _CONTEXTS[key]
    from sim.scenario import ASSETS_DIR
    from sim.simulator import blueprints

    path = ensure_log(cfg.recording, cfg.cache_path(), name=cfg.name, progress=progress)
    log = load_log(path)
    scans, secs = _deterministic_scans(log, cfg.scans, _scans_path(path, cfg.scans), progress)
    bp = blueprints.load_blueprint(ASSETS_DIR / cfg.recording.map)
    vm = bp.vectormap
    query = SceneQuery(vm, load_or_build(vm, ASSETS_DIR / f"{cfg.recording.map}.vectormap.txt", cfg.grid))
    ctx = Context(log, query, scans, secs)
    _CONTEXTS[key] = ctx
    return ctx


# --------------------------------------------------------------------------- one replay


def _hist_edges() -> np.ndarray:
    return np.append(np.arange(0.0, HIST_MAX_M + HIST_STEP_M / 2, HIST_STEP_M), np.inf)


def replay(ctx: Context, cfg: LocComparisonConfig, approach: str, seed: int) -> dict[str, Any]:
    """One offline replay of the log with one approach; JSON-able result."""
    log, q = ctx.log, ctx.query
    n = log.n_frames
    ss = np.random.SeedSequence(int(seed))
    s_odom, s_cgr, s_sense = ss.spawn(3)
    od = cfg.odometry
    noise = np.random.default_rng(s_odom).standard_normal((n, 3))
    inc = log.increments * (1.0 + noise * np.array([od.translation_noise, od.translation_noise, od.rotation_noise]))
    sense_base = int(np.random.default_rng(s_sense).integers(0, 2**31))
    cgr_cfg = dataclasses.replace(cfg.cgr, refinements=0) if approach == "mcl" else cfg.cgr
    obs_cfg = cfg.observation if approach in ("fspf", "mcl") else cfg.laser_observation
    loc = CGRLocalizer(lambda x, y: q.scene_lines(x, y)[0], cgr_cfg, obs_cfg, np.random.default_rng(s_cgr))
    loc.reset(log.poses[0])
    intr, mount, scfg, fcfg = log.intrinsics, log.mount, cfg.scans, cfg.fspf
    # FSPF as the robot stack runs it (sensing only: the replay's filter is ``loc``).
    sensing = RobotStack(
        q.vm, None, StackConfig(DepthCamera(intr, mount), fcfg, LocalizationConfig(enabled=False), navigate=False),
        rng=np.random.default_rng(0),
    )
    errors = np.zeros(n)
    est = np.zeros((n, 3))
    est[0] = loc.estimate().pose
    errors[0] = float(np.hypot(*(est[0, :2] - log.poses[0, :2])))
    proc = 0.0
    locs = 0.0
    depth_m = np.empty((intr.height, intr.width), np.float32)
    cached = ctx.scans.get(approach)
    wall0 = time.perf_counter()
    for k in range(1, n):
        t0 = time.thread_time()
        if approach in ("fspf", "mcl"):
            np.multiply(log.depth_mm[k], np.float32(0.001), out=depth_m, casting="unsafe")
            res = sensing.perceive(depth_m, seed=sense_base + k).planes
            # The lasers' height band applies to FSPF's points too: the approaches differ
            # in how they sample the depth image, not in what they may see.
            p3, n3 = drop_floor(res.points, res.normals, scfg)
            pts, nrm = project_to_floor(p3, n3, fcfg.max_vertical_normal_angle_rad)
        elif approach == "ks":
            pts, nrm = scan_points(sampling_scan(log.depth_mm[k], intr, mount, scfg, seed=sense_base + k), mount, scfg), None
        else:
            pts, nrm = scan_points(cached[k], mount, scfg), None
        t1 = time.thread_time()
        loc.predict(inc[k])
        loc.update(pts, nrm)
        e = loc.estimate().pose
        t2 = time.thread_time()
        proc += t1 - t0
        locs += t2 - t1
        est[k] = e
        errors[k] = math.hypot(e[0] - log.poses[k, 0], e[1] - log.poses[k, 1])
    wall = time.perf_counter() - wall0
    if cached is not None:
        proc += float(ctx.scan_s[approach][1:].sum())  # making the scans, timed once per frame
    bad = np.flatnonzero(errors >= cfg.failure_error_m)
    t_rel = log.t - log.t[0]
    counts = np.histogram(errors, bins=_hist_edges())[0]
    nz = np.flatnonzero(counts)
    counts = counts[: nz[-1] + 1] if len(nz) else counts[:0]
    step = max(1, round(1.0 / (cfg.trace_hz * max(1e-9, float(np.median(np.diff(log.t))) if n > 1 else 1.0))))
    duration = max(log.duration_s, 1e-9)
    return {
        "approach": approach,
        "seed": int(seed),
        "frames": n,
        "failed": bool(len(bad)),
        "failure_t_s": round(float(t_rel[bad[0]]), 4) if len(bad) else None,
        "error_mean_m": round(float(errors.mean()), 5),
        "error_median_m": round(float(np.median(errors)), 5),
        "error_max_m": round(float(errors.max()), 5),
        "error_sum_m": round(float(errors.sum()), 4),
        "error_hist": [int(c) for c in counts],
        "trace_every": step,
        "trace": [[round(float(x), 3), round(float(y), 3)] for x, y in est[::step, :2]],
        "timing": {
            "processing_s": round(proc, 4),
            "localization_s": round(locs, 4),
            "replay_wall_s": round(wall, 3),
            "cpu_load": round(proc / duration, 6),
            "cpu_load_with_localization": round((proc + locs) / duration, 6),
        },
    }


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
    nb = len(_hist_edges()) - 1
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
    edges = _hist_edges()[1:-1]
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
