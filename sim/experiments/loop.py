"""The closed loop of a mission run: one tick is one Kinect frame (1/30 s).

The robot stack decides on the last frame (:class:`autonomy.stack.RobotStack`), the
simulator steps once with its command (:class:`sim.simulator.step.SimStep`: people,
physics, the noisy depth frame, odometry), and the stack perceives and localizes on the
new frame; :mod:`sim.experiments.accounting` keeps what each frame adds, and every stage
is timed. Ctrl-C ends the loop early; an error inside it is kept on the run
(:func:`note_crash`) with every record cut back to the last whole frame.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable

import numpy as np

from autonomy.navigation.config import NavCommand
from autonomy.stack import RobotStack
from sim.experiments.accounting import check_localization, fspf_counts, note_blind, note_contacts
from sim.experiments.kinds import crash_block
from sim.experiments.memory import release_free_memory, resident_mb
from sim.experiments.site import STAGES, Run
from sim.experiments.trace import in_window, trace_record
from sim.experiments.waypoints import close_leg, follow_plan, start_leg
from sim.viz.run_log import RunLogger

#: Resident memory is sampled, after the free heap is returned to the system, every this
#: many frames (30 s of simulated time).
RSS_EVERY = 900


def depth_backend_line(name: str, process: bool = True) -> str:
    """How depth frames are made, in words, with the fix when it is the slow fallback."""
    if name == "gl":
        where = "in a render process" if process else "in this process"
        return f"rendered by MuJoCo through OpenGL {where} (MUJOCO_GL={os.environ.get('MUJOCO_GL', 'default')})"
    return ("ray cast on the CPU (no OpenGL context could be made; about 20x slower than rendering: "
            "install Mesa's EGL with `make gl`)")


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt lies anywhere down ``exc``'s chain of causes."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt):
            return True
        seen.add(id(cur))
        cur = cur.__cause__ if cur.__cause__ is not None else cur.__context__
    return False


def drive(run: Run, recorder: RunLogger | None, progress: bool | None, checkpoint: Callable[[], None] | None = None) -> bool:
    """The closed loop until the mission is done or its time is up; True if interrupted.
    ``checkpoint`` is called every ``report.checkpoint_s`` simulated seconds."""
    scn, mission = run.scn, run.mission
    every = scn.report.checkpoint_s if checkpoint is not None else 0.0
    next_checkpoint = every
    max_frames = int(math.ceil(scn.mission.max_duration_s / run.sim.frame_dt))
    show = progress if progress is not None else (scn.report.progress and sys.stderr.isatty())
    bar = None
    if show:
        from tqdm import tqdm

        bar = tqdm(total=max_frames, unit="frame", desc=scn.name, leave=False)
    try:
        first = run.sim.first()
        if progress is not False and scn.report.progress:
            # The depth backend decides the speed of a run by 20x: say which one this is.
            print(f"{scn.name}: depth camera {depth_backend_line(run.camera.backend_name, run.camera.cfg.render_process)}", file=sys.stderr)
        run.truth.append(first.pose)
        run.times.append(0.0)
        # The first frame, so the navigator sees before it moves.
        run.stack.perceive(first.depth)
        length = run.stack.set_goal(mission.goal, 0.0, mission.start_pose)
        start_leg(mission, scn.mission, length, _plan_nodes(run.stack), 0.0, scn.navigator.cruise_speed_mps)
        while run.frames < max_frames and not mission.done:
            if not tick(run, recorder):
                break
            if every > 0 and run.world.data.time >= next_checkpoint:
                assert checkpoint is not None
                try:
                    checkpoint()
                except OSError as exc:
                    # A full disk should not end a long run: the final report is tried anyway.
                    print(f"{scn.name}: could not write the checkpoint report.json ({exc}); the run goes on without checkpoints", file=sys.stderr)
                    every = 0.0
                next_checkpoint = run.world.data.time + every
            if bar is not None:
                bar.update(1)
                if run.frames % 30 == 0:
                    bar.set_postfix(dist=f"{run.distance_m:.0f}m", wp=f"{mission.reached}/{len(mission.waypoints)}", coll=run.collisions, resets=run.resets)
    except KeyboardInterrupt:
        return True
    except Exception as exc:
        # A bug in the loop: report what finished (run_scenario raises after). But Ctrl-C
        # (or SIGTERM) landing inside a numba kernel comes out as a SystemError caused by
        # the KeyboardInterrupt, one or several levels down: an interruption, not a bug.
        if not _caused_by_interrupt(exc):
            note_crash(run, exc)
        return True
    finally:
        if bar is not None:
            bar.close()
    return False


def tick(run: Run, recorder: RunLogger | None) -> bool:
    """One frame: decide on the last frame, step the simulator, perceive and localize.
    False when the mission has ended this frame."""
    world, stack = run.world, run.stack
    t = float(world.data.time)
    if run.faults is not None:
        nav_ = stack.navigator
        run.faults.before_step(t, run.distance_m, None if nav_ is None or len(nav_.path) < 2 else nav_.path)
    pose = world.robot.pose(world.data)
    control_pose = stack.pose.copy() if run.use_estimate else pose
    override = None if run.use_estimate else pose
    nav = stack.decide(t, override)
    nav_ms = stack.timings_s["navigation"]
    if stack.navigator is not None:
        follow_plan(
            run.mission, run.scn.mission, stack.navigator.plan_nodes, stack.navigator.remaining_m(control_pose), t,
            run.scn.navigator.cruise_speed_mps,
        )
    run.nav_states[nav.state] = run.nav_states.get(nav.state, 0) + 1
    run.near_frames += int(nav.near_points > 0)
    timed_out = t - run.mission.started_at > run.mission.timeout_s
    if nav.state == "arrived" or timed_out:
        nav = next_leg(run, nav, timed_out, pose, control_pose, t, override)
        if nav is None:
            return False
    obstacles = stack.perception.obstacles
    frame = run.sim.step(nav.velocity)
    if run.faults is not None:
        frame = run.faults.filter_frame(frame)
    note_contacts(run, frame, pose, t, nav, control_pose, obstacles)
    stack.perceive(frame.depth)
    run.fspf_counts.append(fspf_counts(stack))
    stack.localize(frame.increment, frame.t)
    if stack.frame_fault:
        run.rejected.append((frame.t, stack.frame_fault))
    check_localization(run, frame)
    if in_window(run.scn.report.trace_s, frame.t):
        run.trace.append(trace_record(frame.t, frame.pose, stack, nav))
    step_m = float(np.hypot(*(frame.pose[:2] - pose[:2])))
    run.distance_m += step_m
    note_blind(run, step_m)
    run.truth.append(frame.pose)
    run.times.append(frame.t)
    run.frames += 1
    t_viz = time.perf_counter()
    if recorder is not None:
        recorder.frame(
            run.frames, frame, stack, nav, world, estimate=run.estimates[-1] if run.localizing else None,
            error_m=run.loc_errors[-1] if run.loc_errors else float("nan"), collisions=run.collisions,
        )
    timings = {**frame.timings_s, **stack.timings_s, "navigation": nav_ms, "viz": time.perf_counter() - t_viz}
    for k in STAGES:
        run.timing[k].append(timings[k])
    if run.frames % RSS_EVERY == 1:
        # Free heap pages go back to the system first (sim.experiments.memory): a long
        # run's resident memory is then what it uses, not the heap's high-water mark.
        release_free_memory()
        run.rss_mb.append((run.frames, resident_mb(), run.distance_m))
    return True


def next_leg(
    run: Run, nav: NavCommand, timed_out: bool, pose: np.ndarray, control_pose: np.ndarray, t: float, override: np.ndarray | None
) -> NavCommand | None:
    """Close the leg that ended; plan the next one and decide again (None: no more)."""
    scn, mission, stack = run.scn, run.mission, run.stack
    close_leg(
        mission, scn.mission, run.building.navgraph, arrived=nav.state == "arrived", timed_out=timed_out, truth_xy=pose[:2],
        t=t, distance_m=run.distance_m, arrival_radius_m=scn.navigator.arrival_radius_m, rng=run.seeds.mission,
        recovering=run.recovering,
    )
    if mission.done:
        return None
    length = stack.set_goal(mission.goal, t, control_pose)
    start_leg(mission, scn.mission, length, _plan_nodes(stack), t, scn.navigator.cruise_speed_mps)
    return stack.decide(t, override)


def _plan_nodes(stack: RobotStack) -> list[int]:
    """The navigator's plan (graph nodes); none without a navigator."""
    return [] if stack.navigator is None else stack.navigator.plan_nodes


def note_crash(run: Run, exc: Exception) -> None:
    """Keep where and how the loop stopped, and end every per-frame record on the last
    whole frame (the failed one may have written some of its rows)."""
    run.crash = {
        **crash_block(exc),
        "t": round(float(run.world.data.time), 4), "frame": run.frames, "distance_m": round(run.distance_m, 3),
    }
    run.crash_exc = exc
    for col in (run.times, run.truth, run.estimates):
        col.truncate(run.frames + 1)
    for col in (run.loc_errors, run.heading_errors, run.fspf_counts, *run.timing.values()):
        col.truncate(run.frames)
