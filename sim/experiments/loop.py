"""The closed loop of a mission run: one tick is one Kinect frame (1/30 s).

The simulator steps once with the command the robot stack decided on the last frame
(:class:`sim.simulator.step.SimStep`: people, physics, the noisy depth frame, odometry),
and the stack steps on the new frame (:meth:`autonomy.stack.RobotStack.step`: perceive,
localize, decide); the loop reads the stack only through that step's output.
:mod:`sim.experiments.accounting` keeps what each frame adds (its localization check
watches the belief between the stack's localizing and deciding, as the paper's operator
did), and every stage is timed. Ctrl-C ends the loop early; an error inside it is kept
on the run (:func:`note_crash`) with every record cut back to the last whole frame.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable

import numpy as np

from autonomy.stack import StackOutput
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
        plan = run.stack.set_goal(mission.goal, 0.0, mission.start_pose)
        start_leg(mission, scn.mission, plan.remaining_m, plan.nodes, 0.0, scn.navigator.cruise_speed_mps)
        # The first frame, so the navigator sees before it moves.
        run.out = run.stack.step(first.depth, None, 0.0, None if run.use_estimate else first.pose, localize=False)
        if run.bag is not None:
            run.bag.start(0.0, first.depth, first.pose, run.out)
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
        end_on_whole_frame(run)
        return True
    except Exception as exc:
        # A bug in the loop: report what finished (run_scenario raises after). But Ctrl-C
        # (or SIGTERM) landing inside a numba kernel comes out as a SystemError caused by
        # the KeyboardInterrupt, one or several levels down: an interruption, not a bug.
        if _caused_by_interrupt(exc):
            end_on_whole_frame(run)
        else:
            note_crash(run, exc)
        return True
    finally:
        if bar is not None:
            bar.close()
    return False


def tick(run: Run, recorder: RunLogger | None) -> bool:
    """One frame: the mission's bookkeeping on the last decision, the simulator step with
    its command, the stack's step on the new frame. False when the mission has ended
    this frame."""
    world, out = run.world, run.out
    t = float(world.data.time)
    if run.faults is not None:
        run.faults.before_step(t, run.distance_m, run.mission.goal)
    pose = world.robot.pose(world.data)
    control_pose = out.estimate if run.use_estimate else pose
    if out.plan is not None:
        follow_plan(run.mission, run.scn.mission, out.plan.nodes, out.plan.remaining_m, t, run.scn.navigator.cruise_speed_mps)
    nav = out.command
    assert nav is not None
    run.nav_states[nav.state] = run.nav_states.get(nav.state, 0) + 1
    run.near_frames += int(nav.near_points > 0)
    timed_out = t - run.mission.started_at > run.mission.timeout_s
    if nav.state == "arrived" or timed_out:
        again = next_leg(run, nav.state == "arrived", timed_out, pose, control_pose, t)
        if again is None:
            return False
        run.out, nav = again, again.command
        assert nav is not None
    obstacles = run.out.perception.obstacles
    frame = run.sim.step(nav.velocity)
    if run.faults is not None:
        frame = run.faults.filter_frame(frame)
    note_contacts(run, frame, pose, t, nav, control_pose, obstacles)
    heavy = recorder is not None and recorder.heavy(run.frames + 1)
    run.out = out = run.stack.step(
        frame.depth, frame.increment, frame.t, None if run.use_estimate else frame.pose,
        operator=lambda sensed: check_localization(run, frame, sensed), correspondences=heavy,
    )
    if run.bag is not None:
        run.bag.frame(frame.t, frame.depth, frame.increment, frame.pose, out)
    run.fspf_counts.append(fspf_counts(out))
    if out.frame_fault:
        run.rejected.append((frame.t, out.frame_fault))
    if in_window(run.scn.report.trace_s, frame.t):
        run.trace.append(trace_record(frame.t, frame.pose, out, nav))
    step_m = float(np.hypot(*(frame.pose[:2] - pose[:2])))
    run.distance_m += step_m
    note_blind(run, step_m)
    run.truth.append(frame.pose)
    run.times.append(frame.t)
    run.frames += 1
    t_viz = time.perf_counter()
    if recorder is not None:
        recorder.frame(
            run.frames, frame, out, nav, world, estimate=run.estimates[-1] if run.localizing else None,
            error_m=run.loc_errors[-1] if run.loc_errors else float("nan"), collisions=run.collisions,
        )
    timings = {**frame.timings_s, **out.timings_s, "viz": time.perf_counter() - t_viz}
    for k in STAGES:
        run.timing[k].append(timings[k])
    if run.frames % RSS_EVERY == 1:
        # Free heap pages go back to the system first (sim.experiments.memory): a long
        # run's resident memory is then what it uses, not the heap's high-water mark.
        release_free_memory()
        run.rss_mb.append((run.frames, resident_mb(), run.distance_m))
    return True


def next_leg(
    run: Run, arrived: bool, timed_out: bool, pose: np.ndarray, control_pose: np.ndarray, t: float
) -> StackOutput | None:
    """Close the leg that ended; plan the next one and decide again (None: no more legs)."""
    scn, mission, stack = run.scn, run.mission, run.stack
    close_leg(
        mission, scn.mission, run.building.navgraph, arrived=arrived, timed_out=timed_out, truth_xy=pose[:2],
        t=t, distance_m=run.distance_m, arrival_radius_m=scn.navigator.arrival_radius_m, rng=run.seeds.mission,
        recovering=run.recovering,
    )
    if mission.done:
        return None
    plan = stack.set_goal(mission.goal, t, control_pose)
    start_leg(mission, scn.mission, plan.remaining_m, plan.nodes, t, scn.navigator.cruise_speed_mps)
    return stack.redecide(t, None if run.use_estimate else pose)


def note_crash(run: Run, exc: Exception) -> None:
    """Keep where and how the loop stopped, and end every per-frame record on the last
    whole frame (the failed one may have written some of its rows)."""
    run.crash = {
        **crash_block(exc),
        "t": round(float(run.world.data.time), 4), "frame": run.frames, "distance_m": round(run.distance_m, 3),
    }
    run.crash_exc = exc
    end_on_whole_frame(run)


def end_on_whole_frame(run: Run) -> None:
    """End every per-frame record on the last whole frame: a frame cut short (by a crash,
    or by Ctrl-C or SIGTERM landing inside the stack's step, which records the estimate
    before the loop records the frame's time) may have written some of its rows."""
    for col in (run.times, run.truth, run.estimates):
        col.truncate(run.frames + 1)
    for col in (run.loc_errors, run.heading_errors, run.fspf_counts, *run.timing.values()):
        col.truncate(run.frames)
