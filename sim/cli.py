"""The ``depthnav`` command line.

Exit codes: 0 success; 2 user error (bad file, key or argument) with one line on stderr
and no traceback; 1 anything else.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from autonomy.errors import InputError


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit 2), as the CLI contract asks."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(f"{self.prog}: {message}")


def _map_arg(text: str) -> Path:
    """A map file, or the name of a building shipped in sim/assets."""
    from sim.scenario import ASSETS_DIR

    p = Path(text)
    if p.exists():
        return p
    asset = ASSETS_DIR / f"{text}.vectormap.txt"
    if asset.exists():
        return asset
    raise InputError(f"{text}: map file not found (give a path or a building in sim/assets)")


def cmd_map_check(args: argparse.Namespace) -> int:
    import numpy as np

    from autonomy.vectormap import load_vectormap

    vm = load_vectormap(args.file)
    xmin, ymin, xmax, ymax = vm.extent()
    print(f"{args.file}: {vm.n_segments} segments")
    print(f"  extent: x [{xmin:.3f}, {xmax:.3f}] m, y [{ymin:.3f}, {ymax:.3f}] m ({xmax - xmin:.2f} x {ymax - ymin:.2f} m)")
    print(f"  total wall length: {vm.total_length_m:.2f} m")
    lengths = vm.lengths
    print(f"  segment length: min {lengths.min():.3f} m, median {float(np.median(lengths)):.3f} m, max {lengths.max():.3f} m")
    return 0


def cmd_map_convert(args: argparse.Namespace) -> int:
    from autonomy.vectormap import load_vectormap, save_vectormap

    vm = load_vectormap(args.input)
    out = save_vectormap(vm, args.output)
    print(f"wrote {out} ({vm.n_segments} segments)")
    return 0


def cmd_map_render(args: argparse.Namespace) -> int:
    from autonomy.vectormap import load_navgraph, load_vectormap
    from sim.viz.maps import render_map

    vm = load_vectormap(args.file)
    graph = load_navgraph(args.graph) if args.graph else None
    out = render_map(vm, args.out, graph, title=Path(args.file).name)
    print(f"wrote {out}")
    return 0


def _parse_pose(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    try:
        vals = tuple(float(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise InputError(f"--pose {text!r}: expected X,Y,THETA (metres, metres, radians), e.g. 2.0,1.5,0.0")
    return vals  # type: ignore[return-value]


def cmd_snapshot(args: argparse.Namespace) -> int:
    import numpy as np

    from autonomy.vectormap import load_vectormap
    from sim.simulator.kinect import KinectCamera, KinectConfig
    from sim.simulator.world import build_world

    pose = _parse_pose(args.pose)
    vm = load_vectormap(_map_arg(args.map))
    x0, y0, x1, y1 = vm.extent()
    if not (x0 - 1 <= pose[0] <= x1 + 1 and y0 - 1 <= pose[1] <= y1 + 1):
        raise InputError(f"--pose {args.pose}: outside the map's extent x [{x0:.1f}, {x1:.1f}], y [{y0:.1f}, {y1:.1f}]")
    # The clean image (--no-noise) keeps everything; the noisy one needs nothing beyond
    # the noise model's range.
    cfg = KinectConfig(backend=args.backend, render_far_m=math.inf if args.no_noise else 0.0)
    world = build_world(vm, intrinsics=cfg.intrinsics, mount=cfg.mount, start_pose=pose)
    cam = KinectCamera(world.model, world.camera_id, cfg)
    depth = cam.render_clean(world.data).copy() if args.no_noise else cam.capture(world.data, args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "depth.npy", depth.astype(np.float32))
    _save_depth_png(depth, out / "depth.png")
    valid = depth > 0
    print(
        f"wrote {out / 'depth.npy'} and {out / 'depth.png'}: {depth.shape[1]}x{depth.shape[0]}, "
        f"{valid.mean() * 100:.1f}% valid, depth {depth[valid].min() if valid.any() else 0:.3f}-"
        f"{depth[valid].max() if valid.any() else 0:.3f} m ({cam.backend_name})"
    )
    cam.close()
    return 0


def _save_depth_png(depth, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np
    from matplotlib import colormaps
    from matplotlib.image import imsave

    d = np.asarray(depth, dtype=np.float64)
    valid = d > 0
    norm = np.clip((d - 0.5) / (4.5 - 0.5), 0, 1)
    rgba = colormaps["turbo"](norm)
    rgba[~valid] = (0, 0, 0, 1)
    imsave(path, rgba)


def cmd_run(args: argparse.Namespace) -> int:
    from sim.experiments.kinds import load_experiment

    exp, scn = load_experiment(args.scenario, args.set or [])
    out = Path(args.out) if args.out else Path("runs") / scn.name
    report = exp.run(scn, out, seed=args.seed, rrd=args.rrd, spawn=args.spawn)
    m = report["metrics"]
    summary = ", ".join(f"{k}={v}" for k, v in m.items())
    print(f"{scn.name}: {summary}")
    print(f"wrote {out / 'report.json'}" + (" (interrupted)" if report["interrupted"] else ""))
    return 130 if report["interrupted"] else 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from sim.experiments.sweep import SweepError, run_sweep

    try:
        report = run_sweep(
            args.scenario, args.set or [], args.out, trials=args.trials, engine=args.engine,
            workers=args.workers, address=args.address, resume=args.resume,
            progress=sys.stderr.isatty(), seed=args.seed,
        )
    except SweepError as exc:
        print(f"depthnav: error: {exc}", file=sys.stderr)
        return 1
    if report["interrupted"]:
        return 130
    m = report["metrics"]
    print(f"{report.get('scenario', args.scenario)}: " + ", ".join(f"{k}={v}" for k, v in m.items()))
    out = Path(report["sweep"]["out_dir"])
    print(f"wrote {out / 'report.json'} ({report['sweep']['trials']} trials in {out / report['sweep']['trials_file']})")
    return 0


def cmd_scenarios(args: argparse.Namespace) -> int:
    from sim.scenario import SCENARIOS_DIR, list_scenarios

    directory = Path(args.dir) if args.dir else SCENARIOS_DIR
    if not directory.is_dir():
        raise InputError(f"{directory}: no such scenario directory")
    items = list_scenarios(directory)
    width = max((len(p.name) for p, _ in items), default=0)
    for p, desc in items:
        print(f"{p.name:<{width}}  {desc}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="depthnav", description="Depth-camera indoor robot autonomy in simulation.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _add_map_commands(sub)
    _add_snapshot_command(sub)
    _add_run_command(sub)
    _add_sweep_command(sub)
    c = sub.add_parser("scenarios", help="list the scenario files")
    c.add_argument("--dir", help="directory (default: the project's scenarios/)")
    c.set_defaults(func=cmd_scenarios)
    return p


def _add_map_commands(sub) -> None:
    pm = sub.add_parser("map", help="inspect, convert and draw vector maps")
    msub = pm.add_subparsers(dest="map_command", required=True, parser_class=_Parser)
    c = msub.add_parser("check", help="validate a map; print segments, extent, wall length")
    c.add_argument("file")
    c.set_defaults(func=cmd_map_check)
    c = msub.add_parser("convert", help="convert between *.vectormap.txt and *.vectormap.json")
    c.add_argument("input")
    c.add_argument("output")
    c.set_defaults(func=cmd_map_convert)
    c = msub.add_parser("render", help="draw a map (and its navigation graph) to PNG")
    c.add_argument("file")
    c.add_argument("--graph", help="a *.navigation.json to draw on top")
    c.add_argument("--out", required=True, help="output PNG")
    c.set_defaults(func=cmd_map_render)


def _add_snapshot_command(sub) -> None:
    c = sub.add_parser("snapshot", help="the Kinect depth frame the robot sees at a pose")
    c.add_argument("map", help="a vector map file or a building name in sim/assets")
    c.add_argument("--pose", required=True, help="X,Y,THETA in metres and radians")
    c.add_argument("--no-noise", action="store_true", help="clean rendered depth")
    c.add_argument("--seed", type=int, default=0, help="noise seed")
    c.add_argument("--backend", default="auto", choices=["auto", "gl", "raycast"])
    c.add_argument("--out", required=True, help="output directory")
    c.set_defaults(func=cmd_snapshot)


def _add_scenario_overrides(c: argparse.ArgumentParser) -> None:
    """``--seed`` and ``--set KEY=VALUE``, as ``run`` and ``sweep`` take them."""
    c.add_argument("--seed", type=int, help="override the scenario's seed")
    c.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a scenario key (repeatable)")


def _add_run_command(sub) -> None:
    c = sub.add_parser("run", help="run a scenario headless and write its report")
    c.add_argument("scenario", help="a scenario TOML file")
    c.add_argument("--out", help="output directory (default runs/<name>)")
    _add_scenario_overrides(c)
    c.add_argument("--rrd", help="write a rerun recording to this file")
    c.add_argument("--spawn", action="store_true", help="open the rerun viewer (needs a display)")
    c.set_defaults(func=cmd_run)


def _add_sweep_command(sub) -> None:
    c = sub.add_parser("sweep", help="run many seeded trials of a scenario (process pool or Ray), resumably")
    c.add_argument("scenario", help="a scenario TOML file")
    c.add_argument("--trials", type=int, help="number of trials (localization_comparison: replays per approach; default: the scenario's replays, else 10)")
    c.add_argument("--engine", default="local", choices=["local", "ray"], help="local process pool (default) or Ray tasks")
    c.add_argument("--address", help="Ray cluster address (default: start a local Ray instance)")
    c.add_argument("--workers", type=int, help="worker processes / local Ray CPUs (default: one per core)")
    c.add_argument("--out", help="output directory (default runs/<name>-sweep)")
    c.add_argument("--resume", action="store_true", help="finish the sweep in --out, keeping its finished trials")
    _add_scenario_overrides(c)
    c.set_defaults(func=cmd_sweep)


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return int(args.func(args))
    except InputError as exc:
        print(f"depthnav: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 1
    except OSError as exc:
        # Paths given on the command line that cannot be read or written.
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"depthnav: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

