"""The ``depthnav map`` and ``depthnav snapshot`` commands: check, graph, convert and
draw vector maps, and the Kinect frame at a pose (:mod:`sim.cli` registers them)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from autonomy.common.errors import InputError
from sim.config import parse_floats


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


def _graph_config(args: argparse.Namespace):
    from autonomy.maps.freespace import FreeSpaceConfig
    from autonomy.maps.graph_builder import GraphBuildConfig

    if not (math.isfinite(args.robot_radius) and args.robot_radius > 0):
        raise InputError(f"--robot-radius: expected a positive number of metres, got {args.robot_radius!r}")
    open_map = True if args.open else False if args.closed else None
    base = FreeSpaceConfig()
    # The grid's margin round the map must hold the robot's footprint and two cells.
    pad = max(base.padding_m, args.robot_radius + 2 * base.cell_m)
    return GraphBuildConfig(free_space=FreeSpaceConfig(robot_radius_m=args.robot_radius, padding_m=pad, open_map=open_map))


def _on_map(path: Path, vm, work):
    """``work()``, with an error about the map named by its path as given (the map's own
    name is the file's stem, which may not say which file)."""
    try:
        return work()
    except InputError as exc:
        msg, stem = str(exc), f"{vm.name}: "
        if vm.name and msg.startswith(stem):
            raise InputError(f"{path}: {msg[len(stem):]}") from None
        raise


def _free_space_lines(fs, how: str) -> list[str]:
    """What ``map check`` says about the grid and an open map."""
    lines = []
    if fs.cell_m != 0.05:
        lines.append(f"  grid: {fs.cell_m:.2f} m cells ({fs.shape[1]} x {fs.shape[0]}), coarser than 0.05 m to fit the "
                     f"extent; clearances are within {fs.error_m:.3f} m, on the safe side")
    if fs.is_open:
        lines.append(f"  open map ({how}): free space is everything within the walls' convex hull "
                     f"({fs.hull_area_m2:.0f} m2) where the robot fits")
    return lines


def cmd_map_check(args: argparse.Namespace) -> int:
    import numpy as np

    from autonomy.maps.graph_builder import build_navgraph
    from autonomy.maps.vectormap import load_vectormap_checked

    path = _map_arg(args.file)
    vm, findings = load_vectormap_checked(path)
    xmin, ymin, xmax, ymax = vm.extent()
    print(f"{path}: {vm.n_segments} segments")
    for f in findings:
        print(f"  {f.severity}: {f}")
    print(f"  extent: x [{xmin:.3f}, {xmax:.3f}] m, y [{ymin:.3f}, {ymax:.3f}] m ({xmax - xmin:.2f} x {ymax - ymin:.2f} m)")
    print(f"  total wall length: {vm.total_length_m:.2f} m")
    lengths = vm.lengths
    print(f"  segment length: min {lengths.min():.3f} m, median {float(np.median(lengths)):.3f} m, max {lengths.max():.3f} m")
    cfg = _graph_config(args)
    gb = _on_map(path, vm, lambda: build_navgraph(vm, cfg))
    fs = gb.free_space
    areas = ", ".join(f"{a:.1f}" for a in fs.region_area_m2[1:6]) + (", ..." if fs.n_regions > 6 else "")
    print(f"  free space for a robot of radius {cfg.free_space.robot_radius_m:.2f} m: {fs.region_area_m2.sum():.1f} m2 "
          f"in {fs.n_regions} region(s); largest {fs.region_area_m2[0]:.1f} m2" + (f"; others {areas} m2" if fs.n_regions > 1 else ""))
    for line in _free_space_lines(fs, "--open" if args.open else "detected: few walls or no inside; --closed to refuse"):
        print(line)
    where = "outside the walls' convex hull" if fs.is_open else "outside the building"
    print(f"  {where}: {fs.outside_area_m2:.1f} m2 (no nodes); voids: {fs.n_voids}")
    main = int(np.count_nonzero(gb.component == 0))
    print(f"  navigation graph: {gb.graph.n_nodes} nodes, {gb.graph.n_edges} edges, {gb.n_components} component(s); "
          f"the largest has {main} nodes")
    if gb.split_regions:
        print(f"  regions {list(gb.split_regions)} fall into several graph components: a passage the robot fits "
              f"only without the {cfg.margin_m:.2f} m margin")
    return 0


def cmd_map_graph(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from autonomy.maps.graph_builder import build_navgraph, graph_key, with_key
    from autonomy.maps.graph_quality import graph_quality
    from autonomy.maps.navgraph import format_navgraph_json
    from autonomy.maps.vectormap import load_vectormap

    cfg = _graph_config(args)
    src = _map_arg(args.file)
    if args.out:
        out = Path(args.out)
    else:
        name = src.name
        for suf in (".vectormap.txt", ".vectormap.json", "_vector.txt", ".txt", ".json"):
            if name.endswith(suf):
                name = name[: -len(suf)]
                break
        out = src.with_name(name + ".navigation.json")
        if out.exists() and not args.force:
            raise InputError(f"{out}: exists (a hand-made graph?); give --out PATH or --force to overwrite it")
    vm = load_vectormap(src)
    t0 = time.perf_counter()
    gb = _on_map(src, vm, lambda: build_navgraph(vm, cfg))
    dt = time.perf_counter() - t0
    out.write_text(with_key(format_navgraph_json(gb.graph), graph_key(vm, cfg)), encoding="utf-8")
    print(f"wrote {out}: {gb.summary()} in {dt:.2f} s")
    for line in _free_space_lines(gb.free_space, "--open" if args.open else "detected; --closed to refuse"):
        print(line)
    if gb.n_components > 1:
        sizes = np.bincount(gb.component)
        print(f"  components by size: {', '.join(str(int(n)) for n in sizes[:8])}{', ...' if sizes.size > 8 else ''} nodes "
              "(the largest is where missions and env episodes run)")
    graphs = [("generated", gb.graph)] if args.quality or args.compare else []
    if args.compare:
        from autonomy.maps.navgraph import load_navgraph

        graphs.append((str(args.compare), load_navgraph(args.compare)))
    for label, g in graphs:
        # the same seed for every graph: the stretch is measured on the same point pairs
        q = graph_quality(g, vm, gb.free_space, np.random.default_rng(0))
        print(f"  {label}: {g.n_nodes} nodes; coverage within {q.cover_radius_m:.1f} m {100 * q.coverage:.1f} %; "
              f"smallest wall clearance {q.min_clearance_m:.3f} m; {q.n_components} component(s); "
              f"path stretch median {q.stretch_median:.3f}, p90 {q.stretch_p90:.3f} ({q.n_pairs} point pairs)")
    if args.png:
        from sim.viz.maps import render_map

        print(f"wrote {render_map(vm, args.png, gb.graph, title=src.name)}")
    return 0


def cmd_map_convert(args: argparse.Namespace) -> int:
    from autonomy.maps.vectormap import load_vectormap, save_vectormap

    if not (math.isfinite(args.scale) and args.scale > 0):
        raise InputError(f"--scale: expected a positive factor (0.001 for millimetres), got {args.scale!r}")
    vm = load_vectormap(args.input, scale=args.scale)
    out = save_vectormap(vm, args.output)
    print(f"wrote {out} ({vm.n_segments} segments)")
    return 0


def cmd_map_render(args: argparse.Namespace) -> int:
    from autonomy.maps.navgraph import load_navgraph
    from autonomy.maps.vectormap import load_vectormap
    from sim.viz.maps import render_map

    src = _map_arg(args.file)
    vm = load_vectormap(src)
    graph = load_navgraph(args.graph) if args.graph else None
    out = render_map(vm, args.out, graph, title=src.name)
    print(f"wrote {out}")
    return 0


def _parse_pose(text: str) -> tuple[float, float, float]:
    return parse_floats(text, "--pose", 3, "X,Y,THETA (metres, metres, radians)", "2.0,1.5,0.0")  # type: ignore[return-value]


def cmd_snapshot(args: argparse.Namespace) -> int:
    import numpy as np

    from autonomy.common.files import output_path
    from autonomy.maps.vectormap import load_vectormap
    from sim.simulator.kinect import KinectCamera, KinectConfig
    from sim.simulator.world import build_world

    pose = _parse_pose(args.pose)
    vm = load_vectormap(_map_arg(args.map))
    out = output_path(args.out, "--out", directory=True)
    x0, y0, x1, y1 = vm.extent()
    if not (x0 - 1 <= pose[0] <= x1 + 1 and y0 - 1 <= pose[1] <= y1 + 1):
        raise InputError(f"--pose {args.pose}: outside the map's extent x [{x0:.1f}, {x1:.1f}], y [{y0:.1f}, {y1:.1f}]")
    # The clean image (--no-noise) keeps everything; the noisy one needs nothing beyond
    # the noise model's range.
    cfg = KinectConfig(backend=args.backend, render_far_m=math.inf if args.no_noise else 0.0)
    world = build_world(vm, intrinsics=cfg.intrinsics, mount=cfg.mount, start_pose=pose)
    cam = KinectCamera(world.model, world.camera_id, cfg)
    depth = cam.render_clean(world.data).copy() if args.no_noise else cam.capture(world.data, args.seed)
    np.save(out / "depth.npy", depth.astype(np.float32))
    sensor = (float(cfg.noise.min_range_m), float(cfg.noise.max_range_m))
    _save_depth_png(depth, out / "depth.png", sensor, args.no_noise)
    valid = depth > 0
    print(
        f"wrote {out / 'depth.npy'} and {out / 'depth.png'}: {depth.shape[1]}x{depth.shape[0]}, "
        f"{valid.mean() * 100:.1f}% valid, depth {depth[valid].min() if valid.any() else 0:.3f}-"
        f"{depth[valid].max() if valid.any() else 0:.3f} m ({cam.backend_name})"
        + (f"; a clean render keeps depths beyond the sensor's {sensor[0]:g}-{sensor[1]:g} m" if args.no_noise else "")
    )
    cam.close()
    return 0


def _save_depth_png(depth, path: Path, sensor_range: tuple[float, float], clean: bool) -> None:
    """The depth image with a colour bar in metres; pixels with no depth (0) in black,
    said so under it, with what the range means for a clean or a noisy image."""
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    d = np.asarray(depth, dtype=np.float64)
    valid = d > 0
    lo, hi = sensor_range
    top = float(d[valid].max()) if clean and valid.any() else hi
    h, w = d.shape
    fig = Figure(figsize=(7.0, 7.0 * h / w + 1.0), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.set_facecolor("black")
    img = ax.imshow(np.ma.masked_where(~valid, d), cmap="turbo", vmin=0.0, vmax=max(top, lo + 0.1), interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    fig.colorbar(img, ax=ax, fraction=0.035, pad=0.02).set_label("depth [m]")
    what = (f"clean render: every depth the far plane keeps, up to {top:.1f} m (the sensor returns {lo:g}-{hi:g} m)"
            if clean else f"Kinect model: returns {lo:g}-{hi:g} m")
    ax.set_title(f"{w}x{h}, {valid.mean() * 100:.1f}% valid; black: no depth\n{what}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)


def _add_open_flags(c) -> None:
    g = c.add_mutually_exclusive_group()
    g.add_argument("--open", action="store_true",
                   help="the walls close no inside (a parking lot, a campus): free space is all of their convex hull")
    g.add_argument("--closed", action="store_true",
                   help="only what the walls enclose is free (default: open when the walls are sparse or enclose almost nothing)")


def add_map_commands(sub, parser_class: type) -> None:
    pm = sub.add_parser("map", help="inspect, convert and draw vector maps")
    msub = pm.add_subparsers(dest="map_command", required=True, parser_class=parser_class)
    c = msub.add_parser("check", help="validate a map; print segments, extent, free space, regions and graph size")
    c.add_argument("file", help="a vector map file or a building name in sim/assets")
    c.add_argument("--robot-radius", type=float, default=0.3, help="robot footprint radius in metres (default 0.3)")
    _add_open_flags(c)
    c.set_defaults(func=cmd_map_check)
    c = msub.add_parser("graph", help="make a navigation graph (navigation.json) from the walls alone")
    c.add_argument("file", help="a vector map file or a building name in sim/assets")
    c.add_argument("--out", help="output *.navigation.json (default: beside the map)")
    c.add_argument("--force", action="store_true", help="overwrite the default output if it exists")
    c.add_argument("--robot-radius", type=float, default=0.3, help="robot footprint radius in metres (default 0.3)")
    _add_open_flags(c)
    c.add_argument("--quality", action="store_true", help="also print coverage, clearance and path stretch")
    c.add_argument("--compare", help="also measure this (e.g. hand-made) *.navigation.json the same way")
    c.add_argument("--png", help="also draw the map and the graph to this PNG")
    c.set_defaults(func=cmd_map_graph)
    c = msub.add_parser("convert", help="convert between *.vectormap.txt and *.vectormap.json (and rescale)")
    c.add_argument("input")
    c.add_argument("output")
    c.add_argument("--scale", type=float, default=1.0, help="multiply coordinates (0.001: a map in millimetres)")
    c.set_defaults(func=cmd_map_convert)
    c = msub.add_parser("render", help="draw a map (and its navigation graph) to PNG")
    c.add_argument("file", help="a vector map file or a building name in sim/assets")
    c.add_argument("--graph", help="a *.navigation.json to draw on top")
    c.add_argument("--out", required=True, help="output PNG")
    c.set_defaults(func=cmd_map_render)


def add_snapshot_command(sub) -> None:
    c = sub.add_parser("snapshot", help="the Kinect depth frame the robot sees at a pose")
    c.add_argument("map", help="a vector map file or a building name in sim/assets")
    c.add_argument("--pose", required=True, help="X,Y,THETA in metres and radians")
    c.add_argument("--no-noise", action="store_true", help="clean rendered depth")
    c.add_argument("--seed", type=int, default=0, help="noise seed")
    c.add_argument("--backend", default="auto", choices=["auto", "gl", "raycast"])
    c.add_argument("--out", required=True, help="output directory")
    c.set_defaults(func=cmd_snapshot)

