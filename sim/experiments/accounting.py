"""What a mission run accumulates frame by frame (:mod:`sim.experiments.loop`): the
contacts and what the robot was doing at each, people in view, the flight recorder,
FSPF's counts, the localization error and the failures it makes, blind driving, and
which injected fault a failure is put down to."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from autonomy.common.geometry import wrap_angle
from autonomy.navigation.config import NavCommand
from autonomy.navigation.surroundings import in_camera_view
from autonomy.stack import StackOutput
from sim.experiments.site import Run
from sim.simulator.actors import furniture_body, person_index
from sim.simulator.step import SimFrame

#: A localization failure starting within this long after an injected fault began (or
#: while it lasts) is that fault's doing.
FAULT_ATTRIBUTION_S = 30.0


def note_contacts(
    run: Run, frame: SimFrame, pose: np.ndarray, t: float, nav: NavCommand, control_pose: np.ndarray, obstacles: np.ndarray
) -> None:
    """People in view, the flight recorder, and what the robot was doing at each new contact."""
    world = run.world
    t_next = t + run.sim.frame_dt
    if len(run.last_in_view):
        run.last_in_view[_people_in_view(run, world.people.positions(), pose)] = t_next
    cmd = nav.velocity
    assert run.blackbox is not None
    run.blackbox.push(frame.t, frame.pose, control_pose, nav, cmd, obstacles, world.people.positions())
    if frame.new_contacts:
        new = world.collision_log[-frame.new_contacts :]
        # What the robot was doing: the navigator's state and the direction it was told
        # to move in (robot frame, degrees), to tell blind-zone contacts apart.
        for ev in new:
            ev["nav_state"] = nav.state
            ev["cmd_dir_deg"] = round(math.degrees(math.atan2(cmd[1], cmd[0])), 1) if np.hypot(cmd[0], cmd[1]) > 1e-6 else None
            for b in ev["bodies"]:
                j = person_index(b)
                if j is not None:
                    ev["person_in_view_s_ago"] = round(t_next - float(run.last_in_view[j]), 2)
        # Fault-placed furniture stands where the fault put it now, not where it was built.
        run.blackbox.on_events(new, furniture=furniture_now(run) if run.faults is not None else ())
    run.collisions += frame.new_contacts


def furniture_now(run: Run) -> list[tuple[float, float, float, tuple[float, float, float]]]:
    """Every furniture piece as (x, y, yaw, dims) where its body stands now (a fault moves
    some: a blockage's panels), for the incident figures."""
    model = run.world.model
    out = []
    for i, f in enumerate(run.furniture):
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, furniture_body(i))
        if b < 0:
            out.append((f.x, f.y, f.yaw, f.dims))
            continue
        q = model.body_quat[b]
        yaw = math.atan2(2.0 * (q[0] * q[3] + q[1] * q[2]), 1.0 - 2.0 * (q[2] ** 2 + q[3] ** 2))
        out.append((float(model.body_pos[b][0]), float(model.body_pos[b][1]), yaw, f.dims))
    return out


def _people_in_view(run: Run, people: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Which people stand inside the camera's horizontal view (field of view, minimum and
    maximum range; occlusion ignored), for the collision log's ``person_in_view_s_ago``."""
    cam = run.robot_camera
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    rel = people[:, :2] - pose[None, :2]
    x = c * rel[:, 0] + s * rel[:, 1] - cam.forward_m
    return in_camera_view(x, -s * rel[:, 0] + c * rel[:, 1], cam)


def fspf_counts(out: StackOutput) -> tuple[int, int, int, int]:
    """The frame's FSPF counts: plane points, outliers, planes, 2D points."""
    per = out.perception
    return (len(per.planes.points), len(per.planes.outliers), per.planes.planes, len(per.points_2d))


def check_localization(run: Run, frame: SimFrame, sensed: StackOutput) -> np.ndarray | None:
    """Errors of the stack's belief on the frame (``sensed``: its output before it
    decides) against the truth, and the failures they make: above
    ``localization.reset_error_m`` a failure starts; it ends when the error is back below
    ``recovered_error_m`` (the robot recovered by itself), or after
    ``truth_reset_after_s`` by re-initialising the belief at the true pose, which this
    returns for the stack to reset to before it decides (counted in
    ``truth_resets_needed``; the paper's operator did this at once). None: no reset."""
    loc = run.scn.localization
    if not sensed.localizing:
        return None
    est = sensed.estimate
    err = float(np.hypot(*(est[:2] - frame.pose[:2])))
    run.loc_errors.append(err)
    run.heading_errors.append(abs(wrap_angle(est[2] - frame.pose[2])))
    run.estimates.append(est)
    run.health_frames[sensed.health_state] = run.health_frames.get(sensed.health_state, 0) + 1
    open_ = run.failures[-1] if run.failures and run.failures[-1]["end_t"] is None else None
    t = frame.t
    if open_ is None:
        if err > loc.reset_error_m:
            run.failures.append(
                {"t": round(t, 3), "x": round(float(frame.pose[0]), 3), "y": round(float(frame.pose[1]), 3), "max_error_m": round(err, 3),
                 "noticed_t": round(t, 3) if sensed.relocalizing else None, "end_t": None, "ended_by": None,
                 "fault": fault_at(run, t) or unknown_start(run, sensed.events)}
            )
            open_ = run.failures[-1]
    if open_ is None:
        return None
    open_["max_error_m"] = max(open_["max_error_m"], round(err, 3))
    if open_["noticed_t"] is None and sensed.relocalizing:
        open_["noticed_t"] = round(t, 3)
    if err < loc.recovered_error_m and not sensed.relocalizing:
        open_.update(end_t=round(t, 3), ended_by="robot")
    elif t - open_["t"] >= loc.truth_reset_after_s:
        open_.update(end_t=round(t, 3), ended_by="truth")
        run.truth_resets += 1
        return frame.pose
    return None


def note_blind(run: Run, step_m: float) -> None:
    """Account the frame's ``step_m`` metres to the blind driving figures: metres CGR
    tracked without an observation update, and the longest such stretch. Where the floor
    shows the camera no wall for metres on end, the belief dead-reckons and its error
    grows with the odometry's (a degree of heading costs 17 cm over 10 m)."""
    out = run.out
    if run.driven_by_own_stack:
        return  # blind driving is CGR's figure; a driver's belief is its own
    if not out.localizing or out.relocalizing:
        # The search, not CGR, holds the belief; what it accepts is a fix.
        run.blind_stretch_m = 0.0
        return
    run.tracked_m += step_m
    stats = out.cgr_stats  # None on a refused frame: dead reckoning as well
    if stats is not None and stats.observation:
        run.blind_stretch_m = 0.0
        return
    run.blind_m += step_m
    run.blind_stretch_m += step_m
    run.blind_stretch_max_m = max(run.blind_stretch_max_m, run.blind_stretch_m)


def fault_events(run: Run) -> list[dict]:
    """The injected faults' events (none without a ``[faults]`` table)."""
    return [] if run.faults is None else run.faults.events


def fault_at(run: Run, t: float) -> str | None:
    """The kind of the injected fault active at ``t`` or begun at most
    ``FAULT_ATTRIBUTION_S`` before it ended (None: no fault)."""
    for ev in reversed(fault_events(run)):
        end = ev["t_end"] if ev.get("t_end") is not None else t
        if ev["t_start"] <= t <= end + FAULT_ATTRIBUTION_S:
            return str(ev["kind"])
    return None


def unknown_start(run: Run, events: tuple[dict, ...]) -> str | None:
    """"unknown start" while a robot started without its pose has not yet found itself
    (no relocalization among the stack's ``events``; its error then is the search's, not
    a failure of the paper's kind); else None."""
    if run.scn.localization.start_known or any(e["event"] == "relocalized" for e in events) or run.truth_resets:
        return None
    return "unknown start"
