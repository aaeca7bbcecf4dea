"""The ``depthnav`` command line.

Exit codes: 0 success; 2 user error (bad file, key or argument) with one line on stderr
and no traceback; 3 a scenario's expectations did not all hold
(:data:`sim.experiments.expect.EXPECTATION_FAILED`); 130 stopped by SIGINT, 143 by
SIGTERM; 1 anything else.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
import warnings
from pathlib import Path

from autonomy.common.errors import InputError
from sim.cli_maps import add_map_commands, add_snapshot_command
from sim.experiments.expect import EXPECTATION_FAILED, summary_line

#: Packages of the ``rl`` extra that policy-research commands import on demand.
RL_PACKAGES = frozenset({"torch", "stable_baselines3", "triton"})


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit 2), as the CLI contract asks."""

    def error(self, message: str) -> None:  # type: ignore[override]
        # main() prints "depthnav: error: ": name the subcommand only ("run: ...").
        sub = self.prog.removeprefix("depthnav").strip()
        raise InputError(f"{sub}: {message}" if sub else message)


def cmd_warmup(args: argparse.Namespace) -> int:
    from sim.warmup import warm_up

    warm_up()
    return 0


def _seed_arg(seed: int | None) -> None:
    """A seed given on the command line: an integer >= 0 (numpy's generators take no other)."""
    if seed is not None and seed < 0:
        raise InputError(f"--seed: expected an integer >= 0, got {seed}")


def cmd_run(args: argparse.Namespace) -> int:
    from autonomy.common.files import output_path
    from sim.experiments.kinds import RunCrashed, load_experiment

    _seed_arg(args.seed)
    exp, scn = load_experiment(args.scenario, args.set or [])
    # Where it writes, checked before the run: a file given as --out, a directory as --rrd.
    out = output_path(args.out if args.out else Path("runs") / scn.name, "--out", directory=True)
    if args.rrd:
        output_path(args.rrd, "--rrd")
    bag = {}
    if args.bag:
        if exp.kind != "mission":
            raise InputError(f"--bag: {scn.name} is a {exp.kind!r} experiment; only mission scenarios are written as bags")
        if not args.bag.endswith(".mcap"):
            raise InputError(f"--bag {args.bag}: expected a file name ending in .mcap (a rosbag2 in MCAP storage)")
        bag = {"bag": output_path(args.bag, "--bag"), "bag_depth": args.bag_depth}
    try:
        report = exp.run(scn, out, seed=args.seed, rrd=args.rrd, spawn=args.spawn, **bag)
    except RunCrashed as exc:
        print(f"depthnav: {scn.name}: {exc}", file=sys.stderr)
        return 1
    print(run_summary(scn.name, report["metrics"]))
    block = report.get("expect", {})
    if block.get("checks"):
        print(summary_line(scn.name, block))
    print(f"wrote {out / 'report.json'}" + (" (every metric)" if _is_mission(report["metrics"]) else "")
          + (" (interrupted)" if report["interrupted"] else ""))
    if report["interrupted"]:
        return 130
    return 0 if block.get("passed", True) else EXPECTATION_FAILED


def _seed_list(text: str | None) -> list[int] | None:
    """``--seeds 1,2,3`` as integers >= 0 (None when not given)."""
    if text is None:
        return None
    try:
        seeds = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--seeds {text!r}: expected integers >= 0 separated by commas, e.g. 0,1,2") from None
    if not seeds or any(v < 0 for v in seeds):
        raise InputError(f"--seeds {text!r}: expected integers >= 0 separated by commas, e.g. 0,1,2")
    return seeds


def cmd_config(args: argparse.Namespace) -> int:
    import dataclasses

    from sim.config import to_dict, to_toml
    from sim.experiments.kinds import load_experiment, shipped_scenario

    exp, cfg = load_experiment(args.scenario, args.set or [])
    data = {f.name: to_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg) if f.name not in ("base_dir", "expect")}
    if isinstance(data.get("avoidance"), dict):
        data["avoidance"].pop("robot_radius_m", None)  # not a key of its own: robot.radius_m
    if exp.kind != "mission":
        data = {"kind": exp.kind, **data}
    expect = getattr(cfg, "expect", ())
    if expect:
        data["expect"] = {e.metric: f"{e.op} {e.value:g}" for e in expect}
    path = shipped_scenario(Path(args.scenario))
    print(f"# {path}: the configuration a run of it uses, every default filled in.\n"
          f"# Relative paths are relative to {cfg.base_dir}.")
    print(to_toml(data), end="")
    return 0


def cmd_test(args: argparse.Namespace) -> int:
    import os
    import time

    from autonomy.common.files import output_path
    from sim.experiments.scenario_tests import (
        ERROR,
        FAILED,
        PASSED,
        junit_xml,
        outcome_line,
        plan_cases,
        run_cases,
    )

    seeds = _seed_list(args.seeds)
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers {args.workers}: expected an integer >= 1")
    junit = output_path(args.junit, "--junit") if args.junit else None
    out = output_path(args.out, "--out", directory=True)
    cases = plan_cases(args.scenario, seeds, args.set or [], out)
    workers = min(args.workers or os.cpu_count() or 1, len(cases))
    print(f"depthnav test: {len(cases)} case{'s' if len(cases) != 1 else ''} on {workers} worker{'s' if workers != 1 else ''}", flush=True)
    t0 = time.perf_counter()
    results, interrupted = run_cases(cases, workers, lambda r: print(outcome_line(r), flush=True))
    wall = time.perf_counter() - t0
    n = {k: sum(r["outcome"] == k for r in results) for k in (PASSED, FAILED, ERROR)}
    print(f"{n[PASSED]} passed, {n[FAILED]} failed, {n[ERROR]} errors in {wall:.0f} s" + (" (interrupted)" if interrupted else ""))
    if junit is not None:
        junit.write_text(junit_xml(results, wall_s=wall), encoding="utf-8")
        print(f"wrote {junit}")
    if interrupted:
        return 130
    return 1 if n[ERROR] else EXPECTATION_FAILED if n[FAILED] else 0


_MISSION_KEYS = ("distance_m", "duration_s", "collisions", "waypoints_reached", "loc_error_p95_m", "resets", "lost_alarms")


def _is_mission(m: dict) -> bool:
    return all(k in m for k in _MISSION_KEYS)


def run_summary(name: str, m: dict) -> str:
    """A mission run's outcome in three short lines (report.json has every metric);
    other kinds' metrics as key=value."""
    if not _is_mission(m):
        return f"{name}: " + ", ".join(f"{k}={v}" for k, v in m.items())

    def cm(key: str) -> str:
        v = m.get(key)
        return "-" if v is None else f"{100 * v:.1f}"

    rtf = m.get("realtime_factor")
    return "\n".join([
        f"{name}: {m['distance_m']:.0f} m in {m['duration_s']:.0f} s" + (f" ({rtf:.1f}x real time)" if rtf else "")
        + f"; waypoints {m['waypoints_reached']} reached, {m.get('waypoints_failed', 0)} failed; contacts {m['collisions']}",
        f"  localization: error mean / p95 / max {cm('loc_error_mean_m')} / {cm('loc_error_p95_m')} / {cm('loc_error_max_m')} cm; "
        f"resets {m['resets']}, truth resets {m.get('truth_resets_needed', 0)}",
        f"  recovery: lost alarms {m['lost_alarms']} (false {m.get('lost_false_alarms', 0)}), relocalizations "
        f"{m.get('relocalizations', 0)}, recovered by the robot {m.get('recovered_by_robot', 0)}",
    ])


def cmd_reloc_sample(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    from autonomy.common.files import output_path
    from sim.experiments.reloc_sample import parse_region, sample
    from sim.experiments.report_file import write_json

    _seed_arg(args.seed)
    region = parse_region(args.region) if args.region else None
    out = output_path(args.out, "--out") if args.out else None  # checked before the long sampling

    def show(tr) -> None:
        x, y, yaw = tr.start
        done = f"relocalized in {tr.seconds:.1f} s, {tr.error_m:.2f} m / {tr.heading_error_deg:.1f} deg off" if tr.relocalized else f"not found in {tr.seconds:.0f} s ({tr.reason})"
        print(f"({x:.2f}, {y:.2f}, {math.degrees(yaw):.0f} deg): {done}", flush=True)

    trials = sample(
        args.map, region, args.n, args.seed, args.seconds, args.noise_m, progress=show, furniture=args.furniture, odometry_noise=args.odometry_noise
    )
    found = [t for t in trials if t.relocalized]
    times = sorted(t.seconds for t in found)
    tail = f", median {times[len(times) // 2]:.1f} s, worst {times[-1]:.1f} s" if times else ""
    print(f"{args.map}: {len(found)} of {len(trials)} unknown starts relocalized within {args.seconds:.0f} s{tail}")
    if out is not None:
        write_json(out, [asdict(t) for t in trials])
        print(f"wrote {out}")
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from sim.experiments.sweep import SweepError, run_sweep

    _seed_arg(args.seed)
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
    name = report.get("scenario", args.scenario)
    print(f"{name}: " + ", ".join(f"{k}={v}" for k, v in m.items()))
    block = report.get("expect")
    if block is not None:
        bad = [t for t in block["trials"] if not t["passed"]]
        print(f"{name}: expectations held on {len(block['trials']) - len(bad)} of {len(block['trials'])} trials"
              + "".join(f"\n  {t['id']}: " + "; ".join(t["failed"]) for t in bad))
    out = Path(report["sweep"]["out_dir"])
    print(f"wrote {out / 'report.json'} ({report['sweep']['trials']} trials in {out / report['sweep']['trials_file']})")
    return 0 if block is None or block["passed"] else EXPECTATION_FAILED


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


def cmd_eval(args: argparse.Namespace) -> int:
    from autonomy.common.files import output_path
    from sim.rl.benchmark_episodes import UnfrozenEpisodesWarning, benchmark_specs
    from sim.rl.evaluate import compare, comparison_table
    from sim.rl.policy_specs import make_policy
    from sim.rl.splits import get_split

    split = get_split(args.split)
    if args.episodes < 1:
        raise InputError(f"--episodes: expected an integer >= 1, got {args.episodes}")
    if args.seed < 0:
        raise InputError(f"--seed: expected an integer >= 0, got {args.seed}")
    if args.task is not None:
        from sim.envs.tasks import TASKS

        if args.task not in TASKS:
            raise InputError(f"--task {args.task}: expected one of {', '.join(TASKS)}")
    policies = [make_policy(spec) for spec in args.policy]  # every spec checked before any episode
    if args.out:
        output_path(args.out, "--out")
    # Val and test run the frozen benchmark episodes; any beyond the file get one note.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UnfrozenEpisodesWarning)
        benchmark_specs(split, args.episodes, args.seed)
    for w in caught:
        if issubclass(w.category, UnfrozenEpisodesWarning):
            print(f"depthnav: note: {w.message}", file=sys.stderr)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UnfrozenEpisodesWarning)
            reports = compare(policies, split, args.episodes, args.seed, progress=not args.no_progress and sys.stderr.isatty(), out=args.out, task=args.task,
                              env_kwargs={"safety_layer": True} if args.safety_layer else None)
    except KeyboardInterrupt:
        print("depthnav: eval interrupted" + (f"; the finished episodes are in {args.out}" if args.out else ""), file=sys.stderr)
        return 130
    print(comparison_table(reports))
    if reports[0].frozen_episodes:
        print(f"{reports[0].frozen_episodes} of the {args.episodes} episodes frozen in {reports[0].episodes_file}; "
              "every reset matched it")
    if args.out:
        print(f"wrote {args.out}")
    return 0


def cmd_demos_record(args: argparse.Namespace) -> int:
    from autonomy.common.files import output_path
    from sim.envs.tasks import TASKS
    from sim.rl.demo_recording import record_demonstrations
    from sim.rl.splits import get_split

    get_split(args.split)
    if args.task not in TASKS:
        raise InputError(f"--task {args.task}: expected one of {', '.join(TASKS)}")
    if args.episodes < 1:
        raise InputError(f"--episodes: expected an integer >= 1, got {args.episodes}")
    if args.seed < 0:
        raise InputError(f"--seed: expected an integer >= 0, got {args.seed}")
    if args.max_steps is not None and args.max_steps < 1:
        raise InputError(f"--max-steps: expected an integer >= 1, got {args.max_steps}")
    if not args.out.endswith(".npz"):
        raise InputError(f"--out: expected a file name ending in .npz, got {args.out!r}")
    output_path(args.out, "--out")
    env_kwargs = None if args.max_steps is None else {"max_steps": args.max_steps}
    try:
        d = record_demonstrations(args.split, args.episodes, args.seed, args.out, env_kwargs,
                                  progress=not args.no_progress and sys.stderr.isatty(), task=args.task)
    except KeyboardInterrupt:
        print(f"depthnav: demos record interrupted; the finished episodes (if any) are in {args.out}", file=sys.stderr)
        return 130
    print(f"wrote {args.out}: {d.n_episodes} episodes, {d.n_steps} steps of the classical stack on {args.task} {args.split}; "
          f"success {d.success.mean():.2f}, SPL {d.spl.mean():.2f}")
    return 0


def cmd_demos_bc(args: argparse.Namespace) -> int:
    from autonomy.common.files import output_path
    from sim.rl.demos import load_demonstrations

    demos = load_demonstrations(args.file)  # a bad file fails before torch is imported
    for name, v in (("--epochs", args.epochs), ("--batch-size", args.batch_size)):
        if v < 1:
            raise InputError(f"{name}: expected an integer >= 1, got {v}")
    if args.seed < 0:
        raise InputError(f"--seed: expected an integer >= 0, got {args.seed}")
    if not (math.isfinite(args.lr) and args.lr > 0):
        raise InputError(f"--lr: expected a positive number, got {args.lr}")
    if args.eval_episodes < 0:
        raise InputError(f"--eval-episodes: expected an integer >= 0, got {args.eval_episodes}")
    output_path(args.out, "--out", directory=True)
    if (Path(args.out) / "model.zip").exists():  # checked before training, not when saving after it
        raise InputError(f"--out {args.out}: holds a stable-baselines3 policy (model.zip); save the behaviour-cloning model elsewhere")
    from sim.rl.bc import train_bc

    policy, hist = train_bc(demos, args.epochs, args.batch_size, args.seed, args.lr)
    for e, (tr, ho) in enumerate(zip(hist["train_loss"], hist["heldout_loss"], strict=True), 1):
        print(f"epoch {e}: train loss {tr:.4f}, held-out MSE {ho:.4f}")
    print(f"held-out MSE {hist['heldout_loss'][-1]:.4f} against {hist['heldout_mean_baseline']:.4f} predicting the mean "
          f"action ({hist['train_steps']} training steps in {hist['train_episodes']} episodes, "
          f"{hist['heldout_steps']} held out in {hist['heldout_episodes']})")
    out = policy.save(args.out, hist)
    print(f"wrote {out}")
    if args.eval_episodes:
        from sim.rl.evaluate import evaluate

        print(evaluate(policy, "val", args.eval_episodes, 0, progress=not args.no_progress and sys.stderr.isatty(), task=policy.task).table())
    return 0


def _env_overrides(items: list[str], task: str, env_kwargs: dict) -> dict:
    """``--env KEY=VALUE`` (VALUE in TOML syntax) as training env kwargs, each key a field
    of the env's configuration (:class:`sim.envs.config.EnvConfig`), checked by building
    ``task``'s configuration with them over the recipe's ``env_kwargs``."""
    import dataclasses

    from sim.config import parse_override
    from sim.envs.config import EnvConfig
    from sim.envs.tasks import TASKS

    fields = {f.name for f in dataclasses.fields(EnvConfig)}
    out = {}
    for text in items:
        path, value = parse_override(text)
        key = ".".join(path)
        if key not in fields:
            raise InputError(f"--env {text!r}: no env setting {key!r} (the fields of sim.envs.config.EnvConfig)")
        out[key] = tuple(value) if isinstance(value, list) else value
    try:
        EnvConfig(**{**TASKS[task], **{k: v for k, v in env_kwargs.items() if k in fields}, **out})
    except (TypeError, ValueError) as exc:
        raise InputError(f"--env: {exc}") from None
    return out


def cmd_train_ppo(args: argparse.Namespace) -> int:
    from autonomy.common.files import output_path
    from sim.envs.tasks import TASKS

    if args.task is not None and args.task not in TASKS:
        raise InputError(f"--task {args.task}: expected one of {', '.join(TASKS)}")

    ints = (("--steps", "total_steps", 1), ("--n-envs", "n_envs", 1), ("--seed", "seed", 0),
            ("--eval-episodes", "eval_episodes", 0), ("--checkpoint-every", "checkpoint_every", 1),
            ("--n-steps", "n_steps", 2), ("--batch-size", "batch_size", 2), ("--n-epochs", "n_epochs", 1))
    given = {}
    for flag, name, low in ints:
        value = getattr(args, name)
        if value is not None and value < low:
            raise InputError(f"{flag}: expected an integer >= {low}, got {value}")
        if value is not None:
            given[name] = value
    if args.learning_rate is not None:
        if not (math.isfinite(args.learning_rate) and args.learning_rate > 0):
            raise InputError(f"--learning-rate: expected a positive number, got {args.learning_rate!r}")
        given["learning_rate"] = args.learning_rate
    if args.vec is not None:
        given["vec"] = args.vec
    if args.log_std_init is not None and not math.isfinite(args.log_std_init):
        raise InputError(f"--log-std-init: expected a finite number, got {args.log_std_init!r}")
    from sim.rl import ppo
    from sim.rl.ppo import HYPERPARAMETERS, PPOTrainConfig, config_with, resume_config

    if args.resume:
        kept = [f"--{k.replace('_', '-')}" for k in HYPERPARAMETERS if k in given]
        kept += [f for f, v in (("--end-on-collision", args.end_on_collision), ("--log-std-init", args.log_std_init), ("--env", args.env)) if v]
        if kept:
            raise InputError(f"{', '.join(kept)}: a resumed run keeps its checkpoint's hyper-parameters; drop them with --resume")
        cfg = resume_config(args.out, **given)
        if args.task is not None and args.task != cfg.task:
            raise InputError(f"--task {args.task}: the run in {args.out} trains {cfg.task}; drop --task with --resume")
    else:
        if args.log_std_init is not None:
            given["policy_kwargs"] = {**ppo.RECIPES.get(args.task or "DepthNav-v0", {}).get("policy_kwargs", {}),
                                      "log_std_init": float(args.log_std_init)}
        output_path(args.out, "--out", directory=True)
        cfg = PPOTrainConfig.for_task(args.task or "DepthNav-v0", out=args.out, **given)
        if args.end_on_collision:
            cfg = config_with(cfg, terminate_on_collision=True)
        if args.env:
            cfg = config_with(cfg, **_env_overrides(args.env, cfg.task, cfg.env_kwargs))
    train_ppo = ppo.train_ppo
    try:
        result = train_ppo(cfg, resume=args.resume, progress=not args.no_progress and sys.stderr.isatty(),
                           log=lambda line: print(line, flush=True))
    except KeyboardInterrupt:  # before training started, or during the final evaluation
        print(f"depthnav: train interrupted; the last checkpoint is in {args.out}", file=sys.stderr)
        return 130
    print(f"{'interrupted' if result.interrupted else 'trained'}: {result.steps} steps, {result.episodes} episodes, "
          f"{result.wall_s / 60:.1f} min in all ({result.session_steps} steps at {result.fps:.0f} steps/s in this run); "
          f"wrote {result.out}/model.zip, policy.json, progress.csv, curve.png")
    if result.eval_summary is not None:
        m = result.eval_summary
        print(f"val ({m['episodes']} episodes): success {m['success']:.3f}, SPL {m['spl']:.3f}, soft-SPL {m['soft_spl']:.3f}, "
              f"collisions {m['collisions']:.2f} per episode; wrote {result.out}/eval.json")
    return 130 if result.interrupted else 0


def cmd_demos_export(args: argparse.Namespace) -> int:
    from sim.rl.demos import export_minari, load_demonstrations

    demos = load_demonstrations(args.file)
    ds = export_minari(demos, args.minari, data_format=args.data_format)
    print(f"wrote Minari dataset {args.minari}: {ds.total_episodes} episodes, {ds.total_steps} steps "
          f"(minari.load_dataset({args.minari!r}))")
    return 0


def _version() -> str:
    """The installed package's version (the checkout's pyproject.toml when not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("depthnav")
    except PackageNotFoundError:
        import tomllib

        return tomllib.loads((Path(__file__).resolve().parent.parent / "pyproject.toml").read_text())["project"]["version"]


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="depthnav", description="Depth-camera indoor robot autonomy in simulation.")
    p.add_argument("--version", action="version", version=f"depthnav {_version()}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    add_map_commands(sub, _Parser)
    add_snapshot_command(sub)
    _add_run_command(sub)
    _add_replay_command(sub)
    _add_test_command(sub)
    c = sub.add_parser("config", help="print a scenario's resolved configuration (every default filled in) as TOML")
    c.add_argument("scenario", help="a scenario TOML file (or the name of one of the project's)")
    c.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a scenario key first (repeatable)")
    c.set_defaults(func=cmd_config)
    _add_sweep_command(sub)
    c = sub.add_parser(
        "reloc-sample",
        help="relocalize from unknown starts at random places of a map, seeing the map alone (docs/recovery.md)",
    )
    c.add_argument("--map", default="corridor_loop", help="a shipped map name or a blueprint path (default corridor_loop)")
    c.add_argument("--region", help="x0,y0,x1,y1: draw the places inside this box (metres; default the whole map)")
    c.add_argument("--n", type=int, default=8, help="number of places (default 8)")
    c.add_argument("--seed", type=int, default=0, help="seed of the places, headings and depth noise (default 0)")
    c.add_argument("--seconds", type=float, default=60.0, help="give up on a place after this long (default 60)")
    c.add_argument("--noise-m", type=float, default=0.003, help="Gaussian depth noise in metres (default 0.003)")
    c.add_argument("--furniture", type=int, default=0, help="random furniture pieces the map lacks in its open areas (default 0)")
    c.add_argument(
        "--odometry-noise", type=float, default=0.0,
        help="relative error on each frame's odometry increments, the scenarios' odometry noise (default 0: exact)",
    )
    c.add_argument("--out", help="also write the trials as JSON to this file")
    c.set_defaults(func=cmd_reloc_sample)
    _add_eval_command(sub)
    _add_demos_command(sub)
    _add_train_command(sub)
    c = sub.add_parser("warmup", help="compile the numba kernels once into the on-disk cache (after pip install)")
    c.set_defaults(func=cmd_warmup)
    c = sub.add_parser("scenarios", help="list the scenario files")
    c.add_argument("--dir", help="directory (default: the project's scenarios/)")
    c.set_defaults(func=cmd_scenarios)
    return p


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
    c.add_argument("--bag", help="also write the run as a rosbag2 in MCAP storage to this .mcap file (docs/rosbag.md)")
    c.add_argument("--bag-depth", choices=("32FC1", "16UC1"), default="32FC1",
                   help="the bag's depth images: float metres (exact, the default) or uint16 millimetres (rounded, as the Kinect's driver writes them)")
    c.set_defaults(func=cmd_run)


def cmd_replay(args: argparse.Namespace) -> int:
    from autonomy.common.files import output_path
    from sim.rosbag.reader import BagTopics
    from sim.rosbag.replay import parse_mount, parse_point, parse_pose, replay_bag, summary

    _seed_arg(args.seed)
    start = parse_pose(args.start, "--start") if args.start else None
    mount = parse_mount(args.mount) if args.mount else None
    out = output_path(args.out if args.out else Path("runs") / f"replay-{Path(args.bag).stem}", "--out", directory=True)
    if args.rrd:
        output_path(args.rrd, "--rrd")
    topics = BagTopics(
        depth=args.depth_topic, camera_info=args.camera_info_topic, odom=args.odom_topic, truth=args.truth_topic,
        base_frame=args.base_frame,
    )
    goal = parse_point(args.goal, "--goal") if args.goal else None
    report = replay_bag(
        args.bag, out, map_path=args.map, start=start, seed=args.seed, scenario=args.scenario, overrides=args.set or [],
        topics=topics, mount=mount, rrd=args.rrd, progress=sys.stderr.isatty(), goal=goal, graph=args.graph,
    )
    print(summary(report))
    print(f"wrote {out / 'report.json'}" + (" (interrupted)" if report["interrupted"] else ""))
    return 130 if report["interrupted"] else 0


def cmd_bag(args: argparse.Namespace) -> int:
    from autonomy.common.files import output_path
    from sim.experiments.drives import load_log
    from sim.rosbag.run_bag import write_drive_bag
    from sim.simulator.blueprints import load_blueprint

    if not args.out.endswith(".mcap"):
        raise InputError(f"--out {args.out}: expected a file name ending in .mcap (a rosbag2 in MCAP storage)")
    log = load_log(args.log)
    walls = load_blueprint(log.map_name).vectormap.segments
    n = write_drive_bag(log, output_path(args.out, "--out"), walls)
    print(f"wrote {args.out}: {n} frames, {log.duration_s:.1f} s, {log.distance_m:.0f} m of {log.map_name}")
    return 0


def _add_replay_command(sub) -> None:
    from sim.rosbag.reader import BagTopics

    d = BagTopics()
    c = sub.add_parser("replay", help="run the robot stack (FSPF, CGR, lost detection) on a ROS bag's depth and odometry (docs/rosbag.md)")
    c.add_argument("bag", help="a rosbag2 (.mcap or .db3 file, or its directory) or a ROS 1 .bag")
    c.add_argument("--map", help="the vector map (a file, or a shipped building's name; default: the walls in a depthnav bag)")
    c.add_argument("--start", help="x,y,theta where the robot starts on the map (default: a depthnav bag's start, "
                   "else the first ground truth, else unknown: the stack finds itself)")
    c.add_argument("--seed", type=int, help="the stack's seed (default: a depthnav bag's run seed, else 0)")
    c.add_argument("--scenario", help="take the stack's configuration from this scenario file (default: a depthnav bag's, else the defaults)")
    c.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a stack key, e.g. localization.cgr.alpha1=0.2 (repeatable)")
    c.add_argument("--out", help="output directory (default runs/replay-<bag name>)")
    c.add_argument("--rrd", help="write a rerun recording to this file")
    c.add_argument("--depth-topic", default=d.depth, help=f"depth images, 32FC1 or 16UC1 (default {d.depth})")
    c.add_argument("--camera-info-topic", default=d.camera_info, help=f"the depth camera's CameraInfo (default {d.camera_info})")
    c.add_argument("--odom-topic", default=d.odom, help=f"wheel odometry, nav_msgs/Odometry (default {d.odom})")
    c.add_argument("--truth-topic", default=d.truth, help=f"ground truth poses, if any, for the error (default {d.truth})")
    c.add_argument("--base-frame", default=d.base_frame, help=f"the robot's frame on the floor in tf (default {d.base_frame})")
    c.add_argument("--mount", help="height,forward,lateral,pitch_deg of the camera on the robot (default: from tf)")
    c.add_argument("--goal", help="x,y: the navigator also decides towards this place on each frame (not actuated; "
                   "its commands go to commands.csv)")
    c.add_argument("--graph", help="the navigation graph for --goal (default: one made from the map's walls)")
    c.set_defaults(func=cmd_replay)
    c = sub.add_parser("bag", help="write a recorded drive (the localization comparison's .log.npz) as a ROS 2 bag (docs/rosbag.md)")
    c.add_argument("log", help="a recorded drive, <cache_dir>/<name>-<key>.log.npz")
    c.add_argument("--out", required=True, help="the bag to write, FILE.mcap")
    c.set_defaults(func=cmd_bag)


def _add_test_command(sub) -> None:
    c = sub.add_parser("test", help="run scenarios as tests of their [expect] tables, in parallel; JUnit XML for CI")
    c.add_argument("scenario", nargs="+", help="scenario TOML files (or names of the project's scenarios)")
    c.add_argument("--junit", metavar="FILE", help="write the outcome as JUnit XML (GitHub Actions, GitLab, Jenkins)")
    c.add_argument("--seeds", metavar="N,N,...", help="run every scenario with each of these seeds (default: each scenario's own)")
    c.add_argument("--workers", type=int, help="scenarios run at once (default: one per core)")
    c.add_argument("--out", default="runs/test", help="where each case writes its report (default runs/test/<scenario>-seed<N>)")
    c.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a key of every scenario (repeatable)")
    c.set_defaults(func=cmd_test)


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


def _add_eval_command(sub) -> None:
    c = sub.add_parser("eval", help="evaluate policies on a building split: success, SPL, soft-SPL, collisions (docs/rl.md)")
    c.add_argument("--policy", nargs="+", required=True, metavar="SPEC",
                   help="random, random:SEED, classical, ppo:PATH or bc:PATH; several: the same episodes each, and a table")
    c.add_argument("--split", default="val", help="train, val (default) or test")
    c.add_argument("--episodes", type=int, default=50, help="number of episodes (default 50)")
    c.add_argument("--seed", type=int, default=0,
                   help="episode seed: which starts and goals (default 0; val and test episodes of seed 0 are the "
                        "frozen benchmark's, sim/rl/episodes/DepthNav-v0.json)")
    c.add_argument("--task", help="the registered task (DepthNav-v0, DepthNavPointGoal-v0, DepthNavLocal-v0); "
                                  "default: the one each policy was trained on (DepthNav-v0 for random and classical)")
    c.add_argument("--safety-layer", action="store_true",
                   help="drive every policy through the robot's safety layer (a task that observes ranges; "
                        "a policy trained with it is always evaluated with it)")
    c.add_argument("--out", help="write the reports (every episode) to this JSON file")
    c.add_argument("--no-progress", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_eval)


def _add_demos_command(sub) -> None:
    pd = sub.add_parser("demos", help="expert demonstrations of the classical stack, and behaviour cloning on them (docs/rl.md)")
    dsub = pd.add_subparsers(dest="demos_command", required=True, parser_class=_Parser)
    c = dsub.add_parser("record", help="record the classical stack's episodes on a split as an .npz dataset")
    c.add_argument("--split", default="train", help="train (default), val or test")
    c.add_argument("--episodes", type=int, default=100, help="number of episodes (default 100)")
    c.add_argument("--seed", type=int, default=0, help="episode seed: which starts and goals (default 0)")
    c.add_argument("--task", default="DepthNav-v0", help="the registered task (default DepthNav-v0; docs/env.md)")
    c.add_argument("--max-steps", type=int, help="shorter episodes than the task's own limit")
    c.add_argument("--out", required=True, help="output .npz file")
    c.add_argument("--no-progress", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_demos_record)
    c = dsub.add_parser("bc", help="train a behaviour-cloning policy on a dataset; print train and held-out loss")
    c.add_argument("file", help="a dataset written by 'depthnav demos record'")
    c.add_argument("--epochs", type=int, default=10, help="passes over the training episodes (default 10)")
    c.add_argument("--batch-size", type=int, default=256, help="steps per gradient step (default 256)")
    c.add_argument("--lr", type=float, default=1e-3, help="Adam's learning rate (default 1e-3)")
    c.add_argument("--seed", type=int, default=0, help="initialisation, shuffling and held-out episodes (default 0)")
    c.add_argument("--out", required=True, help="output directory (model.pt, policy.json)")
    c.add_argument("--eval-episodes", type=int, default=0, help="then evaluate the policy on this many val episodes")
    c.add_argument("--no-progress", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_demos_bc)
    c = dsub.add_parser("export", help="convert a dataset to another format (Minari, if the minari package is installed)")
    c.add_argument("file", help="a dataset written by 'depthnav demos record'")
    c.add_argument("--minari", required=True, metavar="DATASET_ID", help="Minari dataset id, e.g. depthnav/classical-train-v0")
    c.add_argument("--data-format", default="arrow", choices=["arrow", "hdf5"], help="Minari's storage (default arrow)")
    c.set_defaults(func=cmd_demos_export)


def _add_train_command(sub) -> None:
    pt = sub.add_parser("train", help="train a policy on the train split's buildings (docs/rl.md)")
    tsub = pt.add_subparsers(dest="train_command", required=True, parser_class=_Parser)
    c = tsub.add_parser("ppo", help="PPO (stable-baselines3, CNN on depth), resumable; writes model.zip, policy.json, "
                        "progress.csv, curve.png and eval.json")
    c.add_argument("--steps", type=int, required=True, dest="total_steps", metavar="N", help="environment steps in all (with --resume: the new total)")
    c.add_argument("--out", required=True, help="output directory (a saved policy: evaluate with --policy ppo:DIR)")
    c.add_argument("--task", help="the registered task to train on, with its reference recipe (DepthNav-v0, the default; "
                                  "DepthNavPointGoal-v0; DepthNavLocal-v0)")
    c.add_argument("--n-envs", type=int, help="environments stepped together (default 2)")
    c.add_argument("--vec", choices=["subproc", "dummy"], help="subproc: one spawned process per env (default); dummy: in this process")
    c.add_argument("--seed", type=int, help="seed of the policy and the envs (default 0)")
    c.add_argument("--resume", action="store_true", help="continue the run in --out up to --steps")
    c.add_argument("--eval-episodes", type=int, help="episodes of the final evaluation on val (default 50; 0: none)")
    c.add_argument("--checkpoint-every", type=int, help="save model and curve every N steps (default 20000)")
    c.add_argument("--n-steps", type=int, help="rollout steps per env (default 1024)")
    c.add_argument("--batch-size", type=int, help="minibatch size (default 256)")
    c.add_argument("--n-epochs", type=int, help="passes over each rollout (default 4)")
    c.add_argument("--learning-rate", type=float, help="Adam step size (default 3e-4)")
    c.add_argument("--log-std-init", type=float, metavar="X",
                   help="initial log standard deviation of the Gaussian policy (SB3's default: 0, a spread of 1)")
    c.add_argument("--env", action="append", metavar="KEY=VALUE",
                   help="a training env setting over the task's recipe, e.g. clearance_reward=-0.1 (repeatable; the evaluation keeps the task's, "
                        "but a policy trained with safety_layer=true is evaluated with it)")
    c.add_argument("--end-on-collision", action="store_true",
                   help="training episodes end at the first collision (the evaluation still counts them)")
    c.add_argument("--no-progress", action="store_true", help="no progress bar (one line per checkpoint still)")
    c.set_defaults(func=cmd_train_ppo)


_SIGNALLED = [0]
"""The signal that last stopped a command (0: none), for its exit code."""


def interrupt_on_signals() -> dict:
    """SIGINT and SIGTERM stop a command the way Ctrl-C does (it keeps what finished).
    A shell that starts a job in the background without job control sets SIGINT to be
    ignored, and Python then installs no handler: ``kill -INT`` would do nothing.
    Returns the handlers replaced (restored when the command ends)."""

    def stop(signum, _frame):
        _SIGNALLED[0] = signum
        raise KeyboardInterrupt(signal.Signals(signum).name)

    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}


def main(argv: list[str] | None = None) -> int:
    before = interrupt_on_signals()
    _SIGNALLED[0] = 0
    try:
        args = build_parser().parse_args(argv)
        rc = int(args.func(args))
        # An interrupted command returns 130 (128 + SIGINT); stopped by SIGTERM, 143.
        return 128 + _SIGNALLED[0] if rc == 130 and _SIGNALLED[0] else rc
    except InputError as exc:
        print(f"depthnav: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 1
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if top not in RL_PACKAGES:
            raise
        print(f"depthnav: error: this command needs {top}, from the rl extra: pip install -e '.[rl]' "
              "(PyTorch's CPU build first: pip install torch --index-url https://download.pytorch.org/whl/cpu)", file=sys.stderr)
        return 2
    except OSError as exc:
        # Paths given on the command line that cannot be read or written.
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"depthnav: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)


if __name__ == "__main__":
    sys.exit(main())

