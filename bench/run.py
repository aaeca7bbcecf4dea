"""depthnav benchmarks: ``make bench`` prints a table and writes bench/results.json.

Each entry is timed over repeated runs after a warm-up (JIT compilation excluded) on this
machine, and stored as ``{name: {median_ms, min_ms, max_ms, target_ms, paper_ms}}``.
Targets come from the issues; paper figures from the seeds where one exists.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from autonomy.maps.vectormap import load_vectormap, save_vectormap  # noqa: E402
from autonomy.perception.fspf import FSPFConfig, fspf  # noqa: E402
from sim.simulator import blueprints  # noqa: E402
from sim.simulator.actors import Furniture  # noqa: E402
from sim.simulator.blueprints import ASSETS_DIR  # noqa: E402
from sim.simulator.building import random_people  # noqa: E402
from sim.simulator.kinect import KinectCamera, KinectConfig  # noqa: E402
from sim.simulator.kinect_noise import apply_kinect_noise  # noqa: E402
from sim.simulator.world import build_world  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import Result, entry, timeit  # noqa: E402


def bench_maps(results: dict[str, Result], quick: bool) -> None:
    from sim.viz.maps import render_map

    large = blueprints.BuildingConfig.large()
    results["blueprint_large"] = entry(
        timeit(lambda: blueprints.generate_building(large, 0), 2 if quick else 5), target=2000.0
    )
    bp = blueprints.generate_building(large, 0)
    vm = bp.vectormap
    print(f"  large generated map: {vm.n_segments} segments", file=sys.stderr)
    if vm.n_segments < 9000:
        raise SystemExit(f"bench: the large building has {vm.n_segments} < 9000 segments")
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "large.vectormap.txt"
        save_vectormap(vm, p)
        results["map_load_9000"] = entry(timeit(lambda: load_vectormap(p), 3 if quick else 10), target=500.0)
        png = Path(d) / "large.png"
        results["map_render_9000"] = entry(
            timeit(lambda: render_map(vm, png, bp.navgraph, dpi=120), 1 if quick else 3), target=5000.0
        )
    results["world_compile_9000"] = entry(timeit(lambda: build_world(vm), 1 if quick else 3, warmup=0), target=5000.0)
    bench_map_graph(results, quick, vm)
    if not quick:
        bench_campus_graph(results)


#: The campus-scale real map, beside the repository where the real floors are kept.
CAMPUS_MAP = ROOT.parent / "shared" / "maps" / "UT_Campus.vectormap.txt"


def bench_campus_graph(results: dict[str, Result]) -> None:
    """``depthnav map graph`` on the 433 x 489 m UT_Campus map in a fresh process (target:
    under a minute and 4 GB), when the real maps are beside the repository."""
    import resource
    import subprocess

    if not CAMPUS_MAP.is_file():
        print(f"  map_graph_campus: skipped ({CAMPUS_MAP} not found)", file=sys.stderr)
        return
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "sim.cli", "map", "graph", str(CAMPUS_MAP), "--out", str(Path(d) / "g.json")],
                       check=True, capture_output=True, text=True, cwd=ROOT)
        ms = 1000.0 * (time.perf_counter() - t0)
    results["map_graph_campus"] = entry([ms], target=60_000.0)
    results["map_graph_campus"]["peak_rss_gb"] = round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6, 2)


def bench_map_graph(results: dict[str, Result], quick: bool, vm) -> None:
    """The automatic navigation graph of the large floor, with its quality measures."""
    from autonomy.maps.graph_builder import build_navgraph
    from autonomy.maps.graph_quality import graph_quality

    results["map_graph_9000"] = entry(timeit(lambda: build_navgraph(vm), 1 if quick else 3), target=10_000.0)
    gb = build_navgraph(vm)
    q = graph_quality(gb.graph, vm, gb.free_space, np.random.default_rng(0))
    results["map_graph_9000"].update(
        nodes=gb.graph.n_nodes, edges=gb.graph.n_edges, components=q.n_components, regions=q.n_regions,
        coverage=round(q.coverage, 4), coverage_target=0.95, min_clearance_m=round(q.min_clearance_m, 4),
        clearance_target_m=0.35, stretch_median=round(q.stretch_median, 4), stretch_target=1.3,
    )


def bench_localization(results: dict[str, Result], quick: bool) -> None:
    """Scene lines and CGR on the 100 x 100 m generated map (10,499 segments)."""
    from autonomy.localization.cgr import CGRConfig, CGRLocalizer
    from autonomy.localization.observation import ObservationConfig
    from autonomy.maps.raycast import SceneQuery, VisibilityGrid, rays_hit
    from autonomy.stack import LOCALIZATION_GRID

    bp = blueprints.generate_building(blueprints.BuildingConfig.large(), 0)
    vm = bp.vectormap
    t = time.perf_counter()
    grid = VisibilityGrid.build(vm, LOCALIZATION_GRID)
    print(f"  visibility grid: {(time.perf_counter() - t) * 1e3:.0f} ms to build", file=sys.stderr)
    query = SceneQuery(vm, grid)
    nodes = bp.navgraph.node_xy()
    rng = np.random.default_rng(0)
    locs = nodes[rng.integers(len(nodes), size=500)] + rng.normal(0, 0.2, (500, 2))
    it = iter(range(10**7))

    def one_query() -> None:
        x, y = locs[next(it) % len(locs)]
        query.scene_lines(float(x), float(y))

    results["scene_lines_query"] = entry(timeit(one_query, 200 if quick else 2000, warmup=20), target=0.05)

    # 2,000 2D points with normals seen from a pose: exact ray casts on the scene lines.
    pose = np.array([*nodes[len(nodes) // 2], 0.3])
    lines, _ = query.scene_lines(pose[0], pose[1])
    ang = pose[2] + rng.uniform(-np.pi, np.pi, 8000)  # all around, so 2,000 land within range
    idx, tt = rays_hit(lines, pose[0], pose[1], np.column_stack([np.cos(ang), np.sin(ang)]))
    ok = (idx >= 0) & (tt < 6.0)
    ang, idx, tt = ang[ok][:2000], idx[ok][:2000], tt[ok][:2000]
    assert len(ang) == 2000, len(ang)
    pts_w = np.column_stack([np.cos(ang) * tt, np.sin(ang) * tt])
    d = lines[idx, 2:] - lines[idx, :2]
    nrm_w = np.column_stack([-d[:, 1], d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]
    nrm_w *= -np.sign(np.einsum("ij,ij->i", nrm_w, pts_w))[:, None]
    c, s_ = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, s_], [-s_, c]])
    pts, nrm = pts_w @ rot.T, nrm_w @ rot.T
    loc = CGRLocalizer(lambda x, y: query.scene_lines(x, y)[0], CGRConfig(), ObservationConfig(), np.random.default_rng(1))
    loc.reset(pose)

    def one_update() -> None:
        loc.predict(np.array([0.0, 0.0, 0.0]))
        loc.update(pts, nrm)

    results["cgr_update"] = entry(timeit(one_update, 50 if quick else 300, warmup=3), target=2.0)


def _corridor_world():
    bp = blueprints.load_blueprint(ASSETS_DIR / "corridor_loop")
    rng = np.random.default_rng(0)
    people = random_people(bp.navgraph, 4, rng)
    cx = [(a[0] + a[2]) / 2 for a in bp.open_areas] or [0.0]
    cy = [(a[1] + a[3]) / 2 for a in bp.open_areas] or [0.0]
    furniture = (Furniture("table", cx[0] + 1.5, cy[0]), Furniture("box", cx[0] - 1.5, cy[0] + 1.0))
    node = bp.navgraph.node_xy()[0]
    nbr = bp.navgraph.node_xy()[bp.navgraph.index_of(bp.navgraph.neighbors(bp.navgraph.nodes[0].id)[0])]
    yaw = float(np.arctan2(nbr[1] - node[1], nbr[0] - node[0]))
    world = build_world(bp.vectormap, furniture=furniture, people=people, start_pose=(node[0], node[1], yaw))
    return world


def _render_in_process_times(n: int) -> list[float]:
    """``render_depth`` with GL in the rendering process itself (the default goes through
    the render server), timed in a child so Mesa never loads into this one."""
    import subprocess

    code = (
        "import json, sys; sys.path.insert(0, sys.argv[1]); import run as b; w = b._corridor_world(); "
        "cam = b.KinectCamera(w.model, w.camera_id, b.KinectConfig(render_process=False)); "
        f"print(json.dumps(b.timeit(lambda: cam.render_clean(w.data), {n}, warmup=3)))"
    )
    r = subprocess.run([sys.executable, "-c", code, str(Path(__file__).resolve().parent)], capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def _real_floor_paths() -> tuple[Path, Path]:
    return ASSETS_DIR / "maps" / "GHC4.vectormap.txt", ASSETS_DIR / "maps" / "GHC4.navigation.json"


def _real_floor_graph():
    from autonomy.maps.vectormap import load_navgraph

    return load_navgraph(_real_floor_paths()[1])


def _real_floor_world():
    """The shipped real floor, its robot at the first graph node facing a neighbour."""
    vm = load_vectormap(_real_floor_paths()[0], checks=False)
    g = _real_floor_graph()
    node = g.node_xy()[0]
    nbr = g.node_xy()[g.index_of(g.neighbors(g.nodes[0].id)[0])]
    yaw = float(np.arctan2(nbr[1] - node[1], nbr[0] - node[0]))
    return build_world(vm, people=random_people(g, 4, np.random.default_rng(0)), start_pose=(node[0], node[1], yaw))


def _physics_frame(world, t: list[float]) -> None:
    """One 30 Hz frame of physics with the robot driving a slow curve and people walking."""
    world.robot.command(world.data, np.array([0.5, 0.0, 0.3]), 1 / 30)
    t[0] += 1 / 30
    world.people.update(world.data, t[0])
    world.step_frame(round((1 / 30) / world.config.timestep_s))


def _drive_frames(world, cam, physics_frame: Callable[[], None], k: int = 20) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """``k`` noisy Kinect frames and the true poses along the robot's drive."""
    frames, poses = [], []
    for i in range(k):
        physics_frame()
        frames.append(cam.capture(world.data, 1000 + i).copy())
        poses.append(world.robot.pose(world.data))
    return frames, poses


def _stack_frame_samples(vm, graph, frames: list[np.ndarray], poses: list[np.ndarray], cfg: KinectConfig, n: int) -> list[float]:
    """``RobotStack.step`` timed as the closed loop runs it (target 2.5 ms; the paper ran
    FSPF and localization in 16.3% of one core at 30 Hz, 5.4 ms a frame), with the true
    odometry increments. The frames are played forwards and backwards in turn, so the view
    and the odometry stay continuous and the stack keeps tracking: a jump back to the
    first frame is a jump in view, which the lost detector rightly takes for a lost robot,
    and the stack would be timed relocalizing instead. Raises if it leaves tracking."""
    from autonomy.common.geometry import relative_pose
    from autonomy.maps.raycast import SceneQuery, VisibilityGrid
    from autonomy.stack import LOCALIZATION_GRID, RobotStack, StackConfig, StackOutput

    scene = SceneQuery(vm, VisibilityGrid.build(vm, LOCALIZATION_GRID))
    stack = RobotStack(vm, graph, StackConfig(camera=cfg.depth_camera()), rng=np.random.default_rng(0), scene=scene)
    stack.reset(poses[0])
    # The goal: the last node of the part of the graph the robot starts in.
    from autonomy.maps.planner import parts

    label = parts(graph)
    xy = graph.node_xy()
    start = int(np.argmin(np.hypot(xy[:, 0] - poses[0][0], xy[:, 1] - poses[0][1])))
    stack.set_goal(int(graph.nodes[int(np.flatnonzero(label == label[start])[-1])].id), 0.0)
    # 0, 1, ..., k-1, k-2, ..., 1, 0, 1, ...
    order = list(range(len(frames))) + list(range(len(frames) - 2, 0, -1))
    it = iter(range(10**6))
    last = [0]
    out: list[StackOutput | None] = [None]

    def stack_frame() -> None:
        k = next(it)
        j = order[k % len(order)]
        inc = np.zeros(3) if k == 0 else relative_pose(poses[last[0]], poses[j])
        last[0] = j
        # Time advances at 30 Hz as in the loop (remembered obstacles expire after memory_s).
        out[0] = stack.step(frames[j], inc, k / 30.0)

    samples = timeit(stack_frame, n, warmup=3)
    end = out[0]
    assert end is not None
    lost = [e for e in end.events if e.get("event") == "lost"]
    if end.health_state != "ok" or lost:
        raise RuntimeError(f"stack_frame: the stack left tracking ({end.health_state}; {lost[:1]}): the timing is not the tracking path's")
    return samples


def bench_sim(results: dict[str, Result], quick: bool) -> None:
    world = _corridor_world()
    cfg = KinectConfig()
    cam = KinectCamera(world.model, world.camera_id, cfg)
    n = 30 if quick else 200
    results["render_depth"] = entry(timeit(lambda: cam.render_clean(world.data), n, warmup=3))
    results["render_depth_inproc"] = entry(_render_in_process_times(n))
    clean = cam.render_clean(world.data).copy()
    seeds = iter(range(10**6))
    results["kinect_noise"] = entry(
        timeit(lambda: apply_kinect_noise(clean, cfg.intrinsics, cfg.noise, next(seeds)), n, warmup=3), target=2.0
    )
    results["kinect_frame"] = entry(timeit(lambda: cam.capture(world.data, next(seeds)), n, warmup=3), target=15.0)
    t = [0.0]

    def physics_frame() -> None:
        _physics_frame(world, t)

    results["sim_step_frame"] = entry(timeit(physics_frame, n, warmup=3))

    # FSPF on real noisy frames of the corridor world (BV2012 Table I parameters).
    # Paper: FSPF + localization took 16.3% of one core at 30 Hz, 5.4 ms a frame.
    frames, poses = _drive_frames(world, cam, physics_frame)
    fcfg = FSPFConfig()
    it = iter(range(10**6))

    def one_fspf() -> None:
        k = next(it)
        fspf(frames[k % len(frames)], cfg.intrinsics, fcfg, seed=k, mount=cfg.mount)

    results["fspf_frame"] = entry(timeit(one_fspf, n, warmup=3), target=1.0, paper=5.4)

    from autonomy.stack import LocalizationConfig, RobotStack, StackConfig
    from sim.simulator.robot import Odometry, OdometryConfig
    from sim.simulator.step import SimStep

    bp = blueprints.load_blueprint(ASSETS_DIR / "corridor_loop")
    vm = bp.vectormap
    # The whole robot-side stack of a frame: FSPF + CGR + near field + avoidance + navigation.
    results["stack_frame"] = entry(_stack_frame_samples(vm, bp.navgraph, frames, poses, cfg, n), target=2.5, paper=5.4)
    # The same on a real floor (the shipped Gates Hillman Center floor: 2,500 walls drawn
    # by hand, where the scene lines and correspondences cost more than on our buildings).
    real = _real_floor_world()
    real_cam = KinectCamera(real.model, real.camera_id, cfg)
    real_t = [0.0]
    real_frames, real_poses = _drive_frames(real, real_cam, lambda: _physics_frame(real, real_t))
    real_cam.close()
    results["stack_frame_real"] = entry(
        _stack_frame_samples(real.vectormap, _real_floor_graph(), real_frames, real_poses, cfg, n), target=2.5, paper=5.4
    )

    sim = SimStep(world, cam, Odometry(OdometryConfig(), np.random.default_rng(0), world.robot.pose(world.data)), 0)
    # FSPF only: physics + render + noise + FSPF, as demo_frame has always measured.
    fspf_only = StackConfig(camera=cfg.depth_camera(), localization=LocalizationConfig(enabled=False), navigate=False)
    sensing = RobotStack(vm, None, fspf_only, rng=np.random.default_rng(0))

    def closed_frame() -> None:
        frame = sim.step(np.array([0.5, 0.0, 0.3]))
        sensing.step(frame.depth, frame.increment, frame.t)

    # Real-time factor >= 2 at 30 Hz: physics + render + noise + FSPF <= 16.7 ms a frame.
    results["demo_frame"] = entry(timeit(closed_frame, n, warmup=3), target=round(1000 / 30 / 2, 2))
    cam.close()


def print_table(results: dict[str, Result]) -> None:
    print(f"{'benchmark':<22}{'median ms':>11}{'min ms':>10}{'max ms':>10}{'target':>10}{'paper':>10}  ok")
    for name, r in results.items():
        tgt = r["target_ms"]
        ok = "" if tgt is None else ("yes" if r["median_ms"] <= tgt else "NO")
        fmt = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
        print(
            f"{name:<22}{r['median_ms']:>11.3f}{r['min_ms']:>10.3f}{r['max_ms']:>10.3f}"
            f"{fmt(tgt):>10}{fmt(r['paper_ms']):>10}  {ok}"
        )
        for key in ("fspf_speedup", "ransac_speedup"):
            if key in r:
                ours = "FSPF" if key == "fspf_speedup" else "our RANSAC"
                print(f"{'':<22}{ours} is {r[key]}x faster than Open3D's segment_plane on the same frames")
        if "realtime_factor" in r:
            print(f"{'':<22}real-time factor {r['realtime_factor']:.2f} (target >= {r['realtime_factor_target']})")
        if "peak_rss_gb" in r:
            print(f"{'':<22}peak memory {r['peak_rss_gb']:.2f} GB (target < 4)")
        if name == "map_graph_9000":  # the graph's quality beside its targets
            print(
                f"{'':<22}coverage {100 * r['coverage']:.1f} % (>= 95), clearance {r['min_clearance_m']:.3f} m (>= 0.35), "
                f"stretch {r['stretch_median']:.3f} (<= 1.3), {r['nodes']} nodes, {r['components']} components / {r['regions']} regions"
            )


GROUP_NAMES = ["maps", "localization", "sim", "planes", "env", "scans", "viz", "start", "open3d", "recovery", "bag"]


def _groups() -> dict[str, Callable[[dict[str, Result], bool], None]]:
    """Every benchmark group; the subsystem ones live beside this file."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bag_bench import bench_bag
    from env_bench import bench_env
    from loc_bench import bench_scans
    from open3d_bench import bench_open3d
    from planes_bench import bench_planes
    from recovery_bench import bench_recovery
    from start_bench import bench_start
    from viz_bench import bench_viz

    return {
        "maps": bench_maps,
        "localization": bench_localization,
        "sim": bench_sim,
        "planes": bench_planes,
        "env": bench_env,
        "scans": bench_scans,
        "viz": bench_viz,
        "start": bench_start,
        "open3d": bench_open3d,
        "recovery": bench_recovery,
        "bag": bench_bag,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results.json"))
    ap.add_argument("--quick", action="store_true", help="fewer repetitions (smoke test)")
    ap.add_argument("--only", nargs="*", choices=GROUP_NAMES, help="run only these groups")
    args = ap.parse_args(argv)
    groups = _groups()
    results: dict[str, Result] = {}
    for name, fn in groups.items():
        if args.only and name not in args.only:
            continue
        print(f"bench: {name} ...", file=sys.stderr)
        fn(results, args.quick)
    print_table(results)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    old = json.loads(out.read_text()) if out.exists() and args.only else {}
    old.update(results)
    out.write_text(json.dumps(old, indent=2) + "\n")
    print(f"machine: Python {platform.python_version()}, {os.cpu_count()} cores, {platform.platform()}")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
