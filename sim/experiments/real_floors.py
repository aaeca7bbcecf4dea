"""The ``real_floors`` experiment kind: the long run on a list of real floors, one table.

A real-floors scenario is a mission scenario (robot, sensors, actors, mission, ...)
without a ``[map]``: its ``[benchmark]`` section lists the vector maps and the seeds, and
every (map, seed) pair is one trial, a whole closed-loop run of
:func:`sim.experiments.runner.run_scenario` on that map with that seed. Trials run on the
sweep engine (:mod:`sim.experiments.sweep`: a process pool or Ray, ``--resume``, Ctrl-C
keeps what finished); the summary is one table, a row per run and a total row, printed
and written as ``table.md`` and ``table.json`` beside ``report.json``.

``--trials N`` runs the first N of the listed seeds on every map (a quick subset);
``--set mission.target_distance_m=50`` shortens every run.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write_text
from sim.experiments.kinds import Experiment
from sim.experiments.report_file import write_json
from sim.scenario import MapConfig, Scenario

KIND = "real_floors"
#: benchmark.graphs: use a ``NAME.navigation.json`` beside the map when there is one, or
#: always make the graph from the walls (the same builder for every floor).
GRAPHS = ("beside", "walls")
#: The config's ``map`` when the scenario gives none (a benchmark has no one map).
NO_MAP = MapConfig(name="(benchmark.maps)")
#: What a bare map name (no file suffix) stands for.
MAP_SUFFIX = ".vectormap.txt"


@dataclass(frozen=True)
class BenchmarkConfig:
    """Which floors and seeds."""

    maps: tuple[str, ...] = ()
    """Vector maps, each a path relative to ``maps_dir``; a bare name (``"GHC5"``) means
    ``GHC5.vectormap.txt``."""
    maps_dir: str = ""
    """The folder the maps are in, relative to the scenario file (empty: its own folder)."""
    seeds: tuple[int, ...] = ()
    """The seeds run on every map (people, furniture, waypoints and noise derive from each)."""
    graphs: str = "beside"
    """``beside``: a hand-made or shipped ``NAME.navigation.json`` next to the map is its
    graph, else one is made from the walls; ``walls``: always made from the walls."""
    workers: int = 0
    """Processes of ``depthnav run`` (0: one per core); ``depthnav sweep`` has --workers."""

    def __post_init__(self) -> None:
        if len(set(self.seeds)) != len(self.seeds):
            raise InputError(f"benchmark.seeds: each seed once, got {list(self.seeds)}")
        if any(s < 0 for s in self.seeds):
            raise InputError(f"benchmark.seeds: expected integers >= 0, got {list(self.seeds)}")
        if self.graphs not in GRAPHS:
            raise InputError(f"benchmark.graphs {self.graphs!r}: expected one of {', '.join(GRAPHS)}")
        if self.workers < 0:
            raise InputError("benchmark.workers: expected an integer >= 0 (0: one per core)")


@dataclass(frozen=True)
class RealFloorsConfig(Scenario):
    """A mission scenario whose maps come from ``[benchmark]`` (see the module docstring)."""

    map: MapConfig = field(default_factory=lambda: NO_MAP)
    """Not given: every trial runs on one of ``benchmark.maps``."""
    benchmark: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    """The maps and seeds (both required)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        b = self.benchmark
        if not b.maps:
            raise InputError("benchmark.maps: list at least one vector map (in a [benchmark] section, with its seeds)")
        if not b.seeds:
            raise InputError("benchmark.seeds: list at least one seed")
        if self.map != NO_MAP:
            raise InputError("map: a real_floors benchmark runs on the maps of benchmark.maps; remove [map]")
        # Every map must be there now, not after hours of the others.
        for i, (_, path) in enumerate(self.map_paths()):
            if not path.is_file():
                raise InputError(f"benchmark.maps[{i}]: file not found: {path}")
        # The near field depends on the camera, its mount and the sensor's range.
        from autonomy.perception.nearfield import NearField

        cam = self.kinect.depth_camera()
        NearField(cam.intrinsics, cam.mount, cam.min_range_m, self.avoidance.robot_radius_m, self.avoidance.near_field)

    @property
    def replays(self) -> int:
        """The sweep's default trial count: all the listed seeds (per map)."""
        return len(self.benchmark.seeds)

    def map_paths(self) -> list[tuple[str, Path]]:
        """(name, path) of every listed map, in order; the name is the file's without
        its map suffix."""
        b = self.benchmark
        folder = self.resolve(b.maps_dir) if b.maps_dir else Path(self.base_dir or ".")
        out = []
        for entry in b.maps:
            p = Path(entry)
            if not p.suffix:
                p = p.with_name(p.name + MAP_SUFFIX)
            path = Path(os.path.normpath(p if p.is_absolute() else folder / p))
            out.append((map_name(path), path))
        return out


def map_name(path: Path) -> str:
    """``GHC5`` for ``.../GHC5.vectormap.txt`` (and the other map suffixes)."""
    for suffix in (MAP_SUFFIX, ".vectormap.json", ".txt", ".json"):
        if path.name.endswith(suffix):
            return path.name.removesuffix(suffix)
    return path.name


def graph_beside(cfg: RealFloorsConfig, path: Path) -> Path | None:
    """The map's own ``NAME.navigation.json`` when the benchmark uses one, else None."""
    if cfg.benchmark.graphs != "beside":
        return None
    for suffix in (MAP_SUFFIX, ".vectormap.json"):
        if path.name.endswith(suffix):
            nav = path.with_name(path.name.removesuffix(suffix) + ".navigation.json")
            return nav if nav.is_file() else None
    return None


def map_scenario(cfg: RealFloorsConfig, index: int) -> Scenario:
    """The mission scenario of the ``index``-th map: everything but the map as given."""
    _, path = cfg.map_paths()[index]
    nav = graph_beside(cfg, path)
    values = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(Scenario) if f.init}
    values["map"] = MapConfig(vectormap=str(path), navgraph=str(nav) if nav else "")
    return Scenario(**values)


def run(cfg: RealFloorsConfig, out_dir: str | Path, *, seed: int | None = None, rrd=None, spawn: bool = False, progress=None) -> dict:
    """``depthnav run``: every (map, seed) on this machine's cores (the sweep engine's local
    engine; run again into the same directory, an interrupted benchmark resumes)."""
    from sim.experiments.sweep import run_experiment

    if rrd or spawn:
        raise InputError(f"{KIND}: --rrd/--spawn record one run; run that map alone with `depthnav run` and [map] vectormap = ...")
    show = progress if progress is not None else sys.stderr.isatty()
    return run_experiment(
        EXPERIMENTS[KIND], cfg, out_dir, trials=cfg.replays, seed=seed, engine="local", workers=cfg.benchmark.workers or None,
        resume="auto", progress=show, resume_hint=f"run the same `depthnav run` command again with --out {out_dir}",
    )


def trials(cfg: RealFloorsConfig, n: int, seed: int) -> list[dict]:
    """One trial per (map, seed): the first ``n`` listed seeds on every map."""
    seeds = cfg.benchmark.seeds
    if seed != cfg.seed:
        raise InputError(f"--seed {seed}: a {KIND} benchmark runs the seeds of benchmark.seeds (change them with --set 'benchmark.seeds=[...]')")
    if n > len(seeds):
        raise InputError(f"--trials {n}: benchmark.seeds lists {len(seeds)} seed(s) per map; give at most that many, or list more")
    return [
        {"id": f"{i:02d}-{name}-seed{s}", "map_index": i, "map": name, "seed": int(s)}
        for i, (name, _) in enumerate(cfg.map_paths())
        for s in seeds[:n]
    ]


def prepare(cfg: RealFloorsConfig, progress: bool) -> None:
    """Make the navigation graph of every map that has none, once, before the workers
    start: they then read it from the cache instead of each making it."""
    from sim.experiments.site import load_building

    for i in range(len(cfg.map_paths())):
        scn = map_scenario(cfg, i)
        if not scn.map.navgraph:
            load_building(scn)


def trial(cfg: RealFloorsConfig, spec: dict) -> dict:
    """One long run, headless and quiet; what the table needs from its report."""
    from sim.experiments.mission import quiet_report

    scn = map_scenario(cfg, int(spec["map_index"]))
    report = quiet_report(scn, int(spec["seed"]), f"{spec['map']} seed {spec['seed']}")
    statuses = [e.get("status") for e in report["events"]]
    return {
        "map": spec["map"],
        "seed": report["seed"],
        "graph": "file" if scn.map.navgraph else "walls",
        "metrics": report["metrics"],
        "resources": {k: v for k, v in report["resources"].items() if k != "rss_by_distance"},
        "waypoint_timeouts": statuses.count("timeout"),
        "waypoint_wrong_place": statuses.count("wrong_place"),
        "timing_ms": report["timing_ms"],
        # What a failure needs to be traced: each leg's end and each lost alarm, failure
        # and relocalization, with times and places (a seeded run replays exactly).
        "events": report["events"],
        "recovery": report["recovery"],
    }


# --------------------------------------------------------------------------- the table

#: The table's columns: (key, markdown header, digits; None: a count).
COLUMNS: tuple[tuple[str, str, int | None], ...] = (
    ("distance_m", "distance m", 1),
    ("contacts", "contacts", None),
    ("resets", "resets", None),
    ("truth_resets", "truth resets", None),
    ("lost_alarms", "lost alarms", None),
    ("false_alarms", "false alarms", None),
    ("waypoint_timeouts", "wp timeouts", None),
    ("error_mean_cm", "err mean cm", 1),
    ("error_p95_cm", "err p95 cm", 1),
    ("error_max_cm", "err max cm", 1),
    ("blind_pct", "blind %", 0),
    ("blind_stretch_max_m", "longest blind m", 1),
    ("realtime_factor", "RTF", 2),
    ("rss_start_mb", "RSS start MB", 0),
    ("rss_end_mb", "RSS end MB", 0),
    ("frame_ms_start", "frame ms start", 1),
    ("frame_ms_end", "frame ms end", 1),
)
#: Counts the total row adds up.
SUMS = ("distance_m", "contacts", "resets", "truth_resets", "lost_alarms", "false_alarms", "waypoint_timeouts")
#: Per-run figures whose total is the worst run's (a p95 or a peak does not add up).
WORST = ("error_p95_cm", "error_max_cm", "blind_stretch_max_m", "rss_start_mb", "rss_end_mb", "frame_ms_start", "frame_ms_end")


def _cm(m: float | None) -> float | None:
    return None if m is None else round(100.0 * m, 2)


def table_row(result: dict) -> dict:
    """A trial's result as a table row (None where the run has no figure, e.g. the
    error of a run without localization or the memory of one shorter than a sample)."""
    m, r = result["metrics"], result.get("resources", {})
    return {
        "map": result["map"],
        "seed": result["seed"],
        "graph": result.get("graph"),
        "distance_m": m["distance_m"],
        "duration_s": m["duration_s"],
        "wall_time_s": m["wall_time_s"],
        "frames": m["frames"],
        "contacts": m["collisions"],
        "contact_incidents": m.get("collision_incidents"),
        "resets": m.get("resets"),
        "truth_resets": m.get("truth_resets_needed"),
        "lost_alarms": m.get("lost_alarms"),
        "false_alarms": m.get("lost_false_alarms"),
        "waypoints_reached": m["waypoints_reached"],
        "waypoint_timeouts": result["waypoint_timeouts"],
        "waypoint_wrong_place": result.get("waypoint_wrong_place", 0),
        "error_mean_cm": _cm(m.get("loc_error_mean_m")),
        "error_p95_cm": _cm(m.get("loc_error_p95_m")),
        "error_max_cm": _cm(m.get("loc_error_max_m")),
        "blind_pct": None if m.get("blind_share") is None else round(100.0 * m["blind_share"], 1),
        "blind_stretch_max_m": m.get("blind_stretch_max_m"),
        "realtime_factor": m["realtime_factor"],
        "rss_start_mb": r.get("rss_start_mb"),
        "rss_end_mb": r.get("rss_end_mb"),
        "frame_ms_start": r.get("frame_ms_start"),
        "frame_ms_end": r.get("frame_ms_end"),
    }


def total_row(rows: list[dict]) -> dict:
    """The total row: counts and distance summed; the error mean weighted by frames; the
    p95, max, longest blind stretch, memory and frame times the worst run's; the blind
    share weighted by distance; the real-time factor as all
    simulated time over all wall time. A column no run has stays None."""
    def present(key: str) -> list[dict]:
        return [r for r in rows if r.get(key) is not None]

    out: dict[str, Any] = {"map": "total", "seed": None, "runs": len(rows)}
    for key in ("duration_s", "wall_time_s", "frames", "contact_incidents", "waypoints_reached", "waypoint_wrong_place", *SUMS):
        have = present(key)
        out[key] = round(sum(r[key] for r in have), 4) if have else None
    for key in WORST:
        have = present(key)
        out[key] = max(r[key] for r in have) if have else None
    have = present("error_mean_cm")
    weight = sum(r["frames"] for r in have)
    out["error_mean_cm"] = round(sum(r["error_mean_cm"] * r["frames"] for r in have) / weight, 2) if have and weight else None
    have = [r for r in present("blind_pct") if r.get("distance_m")]
    metres = sum(r["distance_m"] for r in have)
    out["blind_pct"] = round(sum(r["blind_pct"] * r["distance_m"] for r in have) / metres, 1) if have and metres else None
    wall = out["wall_time_s"] or 0.0
    out["realtime_factor"] = round(out["duration_s"] / wall, 4) if rows and wall > 0 else None
    km = (out["distance_m"] or 0.0) / 1000.0
    out["resets_per_km"] = round(out["resets"] / km, 4) if out["resets"] is not None and km > 0 else None
    return out


def _cell(v: Any, digits: int | None) -> str:
    if v is None:
        return "–"
    if digits is None:
        return str(int(v))
    return f"{v:.{digits}f}"


def markdown_table(rows: list[dict], total: dict) -> str:
    """The rows and the total row as a markdown table."""
    head = ["map", "seed", *(h for _, h, _ in COLUMNS)]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(" --- " if i < 2 else " ---: " for i in range(len(head))) + "|"]
    for r in [*rows, total]:
        first = [str(r["map"]) if r is not total else f"**total** ({total['runs']} run{'' if total['runs'] == 1 else 's'})", "" if r["seed"] is None else str(r["seed"])]
        lines.append("| " + " | ".join(first + [_cell(r.get(k), d) for k, _, d in COLUMNS]) + " |")
    return "\n".join(lines) + "\n"


def summarize(cfg: RealFloorsConfig, results: list[dict], out_dir: Path) -> dict:
    """The table (printed, ``table.md``, ``table.json``) and ``report.json``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = [table_row(r) for r in results]
    total = total_row(rows)
    md = markdown_table(rows, total)
    atomic_write_text(out_dir / "table.md", md)
    write_json(out_dir / "table.json", {"rows": rows, "total": total})
    print(md, end="")
    metrics = {
        "runs": len(rows),
        **{f"total_{k}": total[k] for k in ("distance_m", "contacts", "resets", "truth_resets", "lost_alarms", "false_alarms", "waypoint_timeouts")},
        "resets_per_km": total["resets_per_km"],
    }
    report = {
        "scenario": cfg.name,
        "kind": KIND,
        "trials": len(rows),
        "interrupted": False,
        "metrics": metrics,
        "maps": [{"name": name, "path": str(path)} for name, path in cfg.map_paths()],
        "seeds": list(cfg.benchmark.seeds),
        "rows": rows,
        "total": total,
        "files": {"table": "table.md", "table_json": "table.json"},
    }
    write_json(out_dir / "report.json", report)
    return report


EXPERIMENTS = {KIND: Experiment(KIND, RealFloorsConfig, run, trials, trial, summarize)}
