"""The replays of the ``localization_comparison`` kind (:mod:`sim.experiments.loc_compare`):
its configuration, what every replay in a process shares (the recorded log, the map's
ray cast, the cached KR / KC scans) and one replay.

A replay runs one approach over the recorded drive (:mod:`sim.experiments.drives`): per
frame, the observation is made from the stored depth frame (FSPF's plane-filtered
points, or a laser scan simulated by KR / KS / KC, :mod:`autonomy.localization.scans`),
CGR predicts with the recorded odometry plus 20% multiplicative noise and updates with
the observation, and the estimate is compared with the recorded truth. Nothing is
rendered again. A replay fails if its error ever reaches 1 m. KR and KC are
deterministic per frame: their scans are computed once per frame (timed, for the CPU
load) and cached beside the log.

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
from sim.simulator.robot import OdometryConfig

#: Approaches: the paper's four, and plain MCL on FSPF's points (CGR without refinement)
#: as an ablation.
APPROACHES = ("fspf", "kr", "ks", "kc", "mcl")

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


def hist_edges() -> np.ndarray:
    """The error histogram's bin edges (``HIST_STEP_M`` up to ``HIST_MAX_M``, then infinity)."""
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
            res = sensing.step(depth_m, None, float(log.t[k]), seed=sense_base + k).perception.planes
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
    counts = np.histogram(errors, bins=hist_edges())[0]
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
