"""A mission run's figures from what its loop recorded (:class:`sim.experiments.site.Run`):
distance, contacts and incidents, waypoints, speed, localization error, failures and
recoveries against the truth, the injected faults' outcomes, FSPF's counts, memory and
frame time."""

from __future__ import annotations

import math

import numpy as np

from sim.experiments.accounting import FAULT_ATTRIBUTION_S, fault_events
from sim.experiments.blackbox import INCIDENT_GAP_S, starts_incident
from sim.experiments.site import STAGES, Run

#: The report's frame times at the start and the end of a run are medians over this many frames.
ENDS_FRAMES = 2000
#: A lost alarm is false when the true error is below this when it is raised.
FALSE_ALARM_ERROR_M = 0.5
#: A fault counts as noticed by the stack within this long of its start ...
NOTICE_WINDOW_S = 60.0
#: ... and the error after it is the largest over this long once it is over.
AFTER_WINDOW_S = 10.0


def resources(run: Run) -> dict:
    """Memory and per-frame time at the start and the end of a run, to show nothing grows
    over a long one: resident MB at the first and last samples and at the peak (and, from
    2 km on, the median over the first and over the last kilometre), the samples against
    the distance driven, and the median frame time (all stages) over the first and last
    ``ENDS_FRAMES`` frames."""
    out: dict = {}
    if run.rss_mb:
        mb = [m for _, m, _ in run.rss_mb]
        out.update(rss_start_mb=round(mb[0], 1), rss_end_mb=round(mb[-1], 1), rss_peak_mb=round(max(mb), 1))
        # The curve itself, every RSS_EVERY frames: [distance m, resident MB].
        out["rss_by_distance"] = [[round(d, 1), round(m, 1)] for _, m, d in run.rss_mb]
        # The first and the last kilometre of a long run (the start includes the warm-up).
        if run.distance_m >= 2000.0:
            first = [m for _, m, d in run.rss_mb if d <= 1000.0]
            last = [m for _, m, d in run.rss_mb if d >= run.distance_m - 1000.0]
            if first and last:
                out.update(rss_first_km_mb=round(float(np.median(first)), 1), rss_last_km_mb=round(float(np.median(last)), 1))
    n = len(run.timing["physics"])
    if n:
        total = np.sum([np.asarray(run.timing[k]) for k in STAGES], axis=0) * 1e3
        k = min(ENDS_FRAMES, n)
        out.update(frame_ms_start=round(float(np.median(total[:k])), 3), frame_ms_end=round(float(np.median(total[-k:])), 3))
    return out


def collision_incidents(events: list[dict], gap_s: float = INCIDENT_GAP_S) -> int:
    """Encounters behind the contact events (``sim.experiments.blackbox.starts_incident``)."""
    last: dict[tuple, float] = {}
    return sum(starts_incident(last, e, gap_s) for e in events)


def truth_at(run: Run, t: float) -> list[float] | None:
    """The true pose [x, y, theta] of the last frame at or before ``t`` (None before the
    first), rounded to the millimetre. The stack's events carry times rounded to the
    millisecond, so a frame up to half a millisecond after ``t`` counts as at it."""
    k = int(np.searchsorted(np.asarray(run.times), t + 5e-4, side="right")) - 1
    if k < 0 or k >= len(run.truth):
        return None
    return [round(float(v), 3) for v in np.asarray(run.truth[k])[:3]]


def fault_report(run: Run) -> list[dict]:
    """Per injected fault: when it happened and the true pose before and after it started
    (a kidnapping's two places), where a blockage stood, when the stack noticed it (its first lost, blind or
    mount-corrected event, or a frame it refused, after the start) and the true pose
    then, when it was over for the robot (kidnap: its relocalization; the others: the
    fault's end, then the error back below ``recovered_error_m``), the true error before
    and after, the contacts in between."""
    out = []
    times = np.array(run.times[1 : 1 + len(run.loc_errors)])
    errs = np.array(run.loc_errors)
    ok_m = run.scn.localization.recovered_error_m
    signals = [(e["t"], e["event"]) for e in run.out.events if e["event"] in ("lost", "blind", "mount corrected")]
    signals += [(t, f"frame {why}") for t, why in run.rejected]
    signals.sort()
    relocs = [e["t"] for e in run.out.events if e["event"] == "relocalized"]
    for ev in fault_events(run):
        t0 = float(ev["t_start"])
        end = float(ev["t_end"]) if ev.get("t_end") is not None else (float(run.times[-1]) if ev["kind"] != "kidnap" else t0)
        rec = {k: ev[k] for k in ("kind", "t_start", "t_end", "distance_m", "truth_before", "truth_after", "where") if k in ev}
        if ev.get("skipped"):
            rec["skipped"] = ev["skipped"]
        seen = [(t, what) for t, what in signals if t0 <= t <= t0 + NOTICE_WINDOW_S]
        rec["noticed_t"] = round(seen[0][0], 3) if seen else None
        rec["noticed_by"] = seen[0][1] if seen else None
        rec["truth_noticed"] = truth_at(run, seen[0][0]) if seen else None
        k0 = int(np.searchsorted(times, t0)) if len(times) else 0
        rec["error_before_m"] = round(float(errs[max(k0 - 1, 0)]), 3) if len(errs) else None
        if ev["kind"] == "kidnap":
            # Its failure (the error it caused), ended by the robot's relocalization or by the truth.
            mine = [f for f in run.failures if f.get("fault") == "kidnap" and t0 - 1.0 <= f["t"] <= t0 + FAULT_ATTRIBUTION_S]
            if mine and mine[0]["ended_by"] == "truth":
                done, rec["ended_by"] = None, "truth"
            else:
                nxt = min([float(e["t_start"]) for e in fault_events(run) if float(e["t_start"]) > t0], default=math.inf)
                after = [t for t in relocs if t0 <= t < nxt]
                done = after[0] if after else None
                rec["ended_by"] = "robot" if done is not None else None
        else:
            k1 = int(np.searchsorted(times, end))
            back = np.flatnonzero(errs[k1:] < ok_m) if k1 < len(errs) else np.zeros(0, np.int64)
            done = float(times[k1 + int(back[0])]) if len(back) else None
        rec["recovered_t"] = round(done, 3) if done is not None else None
        rec["recovery_s"] = round(done - t0, 3) if done is not None else None
        if done is not None and len(times):
            a, b = np.searchsorted(times, done), np.searchsorted(times, done + AFTER_WINDOW_S)
            rec["error_after_m"] = round(float(errs[a:b].max()), 3) if b > a else None
        last = (done if done is not None else end) + AFTER_WINDOW_S
        rec["contacts"] = sum(t0 <= c["t"] <= last for c in run.world.collision_log)
        out.append(rec)
    return out


def recovery_metrics(run: Run) -> dict:
    """Lost alarms against the truth (false alarms: raised while the error was below
    ``FALSE_ALARM_ERROR_M``; misses: failures the robot never noticed before they ended),
    relocalizations, rejected frames, and the failures' detection and recovery times."""
    out = run.out
    times = np.array(run.times[1 : 1 + len(run.loc_errors)])
    errs = np.array(run.loc_errors)
    lost = [e for e in out.events if e["event"] == "lost"]
    false_alarms = 0
    for e in lost:
        k = int(np.searchsorted(times, e["t"] - 1e-9)) if len(times) else 0
        if k < len(errs) and errs[k] < FALSE_ALARM_ERROR_M:
            false_alarms += 1
    failures = run.failures
    noticed = [f["noticed_t"] - f["t"] for f in failures if f["noticed_t"] is not None]
    recovered = [f["end_t"] - f["t"] for f in failures if f["ended_by"] == "robot"]
    return {
        "loc_failures": len(failures),
        "loc_failures_faults": sum(f.get("fault") is not None for f in failures),
        "lost_alarms": len(lost),
        "lost_false_alarms": false_alarms,
        "lost_misses": sum(f["noticed_t"] is None for f in failures),
        "relocalizations": sum(e["event"] == "relocalized" for e in out.events),
        "recovered_by_robot": sum(f["ended_by"] == "robot" for f in failures),
        "recovery_time_median_s": round(float(np.median(recovered)), 2) if recovered else None,
        "recovery_time_max_s": round(float(np.max(recovered)), 2) if recovered else None,
        "notice_time_median_s": round(float(np.median(noticed)), 2) if noticed else None,
        "frames_dropped": out.frames_rejected["dropped"],
        "frames_stale": out.frames_rejected["stale"],
        "frames_invalid": out.frames_rejected["invalid"],
        "frames_corrupt": out.frames_rejected["corrupt"],
        "relocalizing_frames": run.health_frames.get("relocalizing", 0),
        "blind_frames": run.health_frames.get("blind", 0),
        **fault_metrics(fault_report(run)),
    }


def fault_metrics(report: list[dict]) -> dict:
    """Injected faults and kidnappings in numbers: how many, how many recovered, and the
    kidnappings' median and worst time to recover (without truth)."""
    if not report:
        return {}
    kid = [r for r in report if r["kind"] == "kidnap" and not r.get("skipped")]
    times = [r["recovery_s"] for r in kid if r["recovery_s"] is not None]
    return {
        "faults_injected": sum(not r.get("skipped") for r in report),
        "faults_recovered": sum(r["recovered_t"] is not None for r in report if not r.get("skipped")),
        "kidnappings": len(kid),
        "kidnappings_recovered": len(times),
        "kidnap_recovery_median_s": round(float(np.median(times)), 2) if times else None,
        "kidnap_recovery_max_s": round(float(np.max(times)), 2) if times else None,
    }


def run_metrics(run: Run, wall_s: float) -> dict:
    """The report's metrics: distance, contacts, waypoints, speed, localization, FSPF."""
    world, mission = run.world, run.mission
    sim_time = float(world.data.time)
    metrics = {
        "frames": run.frames,
        "distance_m": round(run.distance_m, 4),
        "duration_s": round(sim_time, 4),
        "collisions": run.collisions,
        **{f"collisions_{k}": sum(k in c["with"] for c in world.collision_log) for k in ("wall", "furniture", "person")},
        "collision_incidents": collision_incidents(world.collision_log),
        "waypoints_reached": mission.reached,
        "waypoints_failed": mission.failed,
        "waypoints_unvisited": mission.unvisited,
        "realtime_factor": round(sim_time / wall_s, 4) if wall_s > 0 else 0.0,
        "wall_time_s": round(wall_s, 3),
    }
    if run.loc_errors:
        e = np.array(run.loc_errors)
        metrics.update(
            {
                "resets": run.resets,
                "resets_per_km": round(run.resets / max(run.distance_m / 1000.0, 1e-9), 4),
                "truth_resets_needed": run.truth_resets,
                **recovery_metrics(run),
                "loc_error_mean_m": round(float(e.mean()), 4),
                "loc_error_median_m": round(float(np.median(e)), 4),
                "loc_error_p95_m": round(float(np.percentile(e, 95)), 4),
                "loc_error_max_m": round(float(e.max()), 4),
                "loc_heading_error_mean_deg": round(math.degrees(float(np.mean(run.heading_errors))), 3),
                "blind_share": round(run.blind_m / run.tracked_m, 4) if run.tracked_m > 0 else None,
                "blind_stretch_max_m": round(run.blind_stretch_max_m, 2),
            }
        )
    if run.fspf_counts:
        c = np.array(run.fspf_counts, dtype=np.float64)
        metrics.update(
            {
                "fspf_plane_points_mean": round(float(c[:, 0].mean()), 2),
                "fspf_outliers_mean": round(float(c[:, 1].mean()), 2),
                "fspf_planes_mean": round(float(c[:, 2].mean()), 2),
                "fspf_points_2d_mean": round(float(c[:, 3].mean()), 2),
            }
        )
    return metrics
