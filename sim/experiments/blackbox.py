"""A flight recorder for collisions: the last seconds before each incident, kept.

A 4 km run takes half an hour; replaying it to see one contact takes as long again. The
runner therefore keeps a ring buffer of what mattered each frame (true and estimated
pose, the navigator's state, command and chosen direction, the nearest sensed obstacle,
where every person stood) and, when a collision incident begins, freezes a copy of it.
``incidents.json`` holds those copies and ``incidents.png`` draws each one over the map:
the robot's track, the people's tracks, the furniture (also pieces a fault placed or moved
during the run), where contact was made. Every body a contact names is drawn; a panel
whose incident names one it cannot draw says so in its title (and a warning is raised).
"""

from __future__ import annotations

import math
import os
import warnings
from collections import deque
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

import numpy as np

from autonomy.common.constants import ROBOT_RADIUS_M
from autonomy.common.errors import InputError
from autonomy.common.geometry import rectangle_corners
from sim.simulator.actors import furniture_body, person_body, person_index

__all__ = ["FlightRecorder", "footprints", "render_incidents", "starts_incident", "undrawn_bodies"]


INCIDENT_GAP_S = 3.0
"""Contacts with the same bodies less than this apart are one incident."""


def starts_incident(last: dict[tuple, float], event: dict, gap_s: float = INCIDENT_GAP_S) -> bool:
    """Whether a contact event begins a new incident: its bodies were not touched in the
    last ``gap_s`` (contact is made and broken many times while the robot and a person
    push against each other). Updates ``last`` (bodies -> time last touched)."""
    key = tuple(event.get("bodies", event.get("with", ())))
    new = key not in last or event["t"] - last[key] > gap_s
    last[key] = event["t"]
    return new


class FlightRecorder:
    """Ring buffer of per-frame state; a new collision incident freezes a copy of it.

    ``push`` only keeps references (a few microseconds a frame); the records are built
    when an incident is frozen, so a run without contacts pays almost nothing.
    """

    def __init__(self, seconds: float, rate_hz: float) -> None:
        self.frames = max(1, int(round(seconds * rate_hz)))
        self._buf: deque[tuple] = deque(maxlen=self.frames)
        self.incidents: list[dict] = []
        self._last: dict[tuple, float] = {}

    def push(self, t: float, truth: np.ndarray, estimate: np.ndarray, nav, cmd: np.ndarray, obstacles: np.ndarray, people: np.ndarray) -> None:
        """One frame: true and estimated pose, the navigator's ``NavCommand`` and the
        velocity sent, the sensed obstacles (robot frame) and the people (n, 2+). The
        arrays must not be modified afterwards (the runner makes new ones each frame)."""
        self._buf.append((t, truth, estimate, nav, cmd, obstacles, people))

    def on_events(self, events: list[dict], furniture: Sequence = (), boxes: Mapping[str, object] | None = None) -> None:
        """Freeze the buffer for each event that starts a new incident (``starts_incident``).

        ``furniture`` / ``boxes`` (as :func:`footprints` takes them): where the furniture
        stands now; given, each new incident keeps a copy (``"furniture"``), which its
        panel draws instead of the pieces passed to :func:`render_incidents` (a fault may
        move a piece away again before the run ends)."""
        for e in events:
            if starts_incident(self._last, e):
                inc = {"event": dict(e), "trace": [frame_record(*f) for f in self._buf]}
                if len(furniture) or boxes:
                    inc["furniture"] = footprints(furniture, boxes)
                self.incidents.append(inc)


def frame_record(
    t: float,
    truth: np.ndarray,
    estimate: np.ndarray,
    nav,
    cmd: np.ndarray,
    obstacles: np.ndarray,
    people: np.ndarray,
) -> dict:
    """One frame as JSON: poses, navigator decision, nearest obstacle, people."""
    near = None
    if len(obstacles):
        k = int(np.argmin(np.hypot(obstacles[:, 0], obstacles[:, 1])))
        near = [round(float(obstacles[k, 0]), 3), round(float(obstacles[k, 1]), 3)]
    return {
        "t": round(float(t), 3),
        "truth": [round(float(v), 4) for v in truth[:3]],
        "estimate": [round(float(v), 4) for v in estimate[:3]],
        "state": nav.state,
        "cmd": [round(float(v), 3) for v in cmd[:3]],
        "desired_deg": round(math.degrees(nav.desired_rad), 1),
        "theta_star_deg": round(math.degrees(nav.theta_star_rad), 1),
        "open_m": round(float(nav.open_length_m), 3) if math.isfinite(nav.open_length_m) else None,
        "n_obstacles": int(len(obstacles)),
        "nearest_obstacle": near,
        "near_points": int(nav.near_points),
        "people": [[round(float(p[0]), 3), round(float(p[1]), 3)] for p in people],
    }


_ROBOT_COLOR = "#1f77b4"
_PERSON_COLOR = "#d62728"
_FURNITURE_COLOR = "burlywood"
_COMMAND_COLOR = "#2ca02c"
_MAX_PANELS = 12
_VIEW_HALF_M = 3.0
"""Each panel shows this far round the contact."""
_PERSON_NEAR_M = 4.0
"""A person's track is drawn when it passes this close to the contact."""


def footprints(furniture: Sequence = (), boxes: Mapping[str, object] | None = None) -> list[dict]:
    """Named footprints of furniture: item ``i`` of ``furniture`` is the body
    ``furniture_<i>`` (the simulator's names, fault-placed pieces included), ``boxes``
    further bodies by name. Each piece is a :class:`sim.simulator.actors.Furniture` or an
    ``(x, y, yaw, dims)`` tuple (dims: length and width, a height may follow), where it
    stands now. Returns dicts with body, label, x, y, yaw and size (length, width)."""
    out = []
    named = [(furniture_body(i), f, i) for i, f in enumerate(furniture)] + [(str(k), f, None) for k, f in (boxes or {}).items()]
    for body, f, i in named:
        if hasattr(f, "dims"):
            kind, x, y, yaw, dims = f.kind, f.x, f.y, f.yaw, f.dims
        else:
            try:
                x, y, yaw, dims = f
                dims = tuple(dims)
            except (TypeError, ValueError):
                raise InputError(f"incident figure: furniture {body}: expected a Furniture or (x, y, yaw, dims), got {f!r}") from None
            kind = "box"
        if len(dims) < 2:
            raise InputError(f"incident figure: furniture {body}: expected dims (length, width[, height]), got {dims!r}")
        label = f"{kind} {i}" if i is not None else body
        out.append({
            "body": body, "label": label, "x": round(float(x), 3), "y": round(float(y), 3), "yaw": round(float(yaw), 4),
            "size": [round(float(dims[0]), 3), round(float(dims[1]), 3)],
        })
    return out


def undrawn_bodies(incident: dict, drawn: list[dict]) -> list[str]:
    """The bodies the incident's contact names that its panel does not draw: the walls
    (``world``) are drawn, so are the ``drawn`` footprints (:func:`footprints`) and each
    person ``person_<j>`` the trace holds."""
    tr = incident.get("trace", [])
    n_people = max((len(f.get("people", [])) for f in tr), default=0)
    have = {"world"} | {f["body"] for f in drawn} | {person_body(j) for j in range(n_people)}
    return [b for b in incident["event"].get("bodies", []) if b not in have]


def render_incidents(
    incidents: list[dict],
    walls: np.ndarray,
    out_png: str | os.PathLike[str],
    robot_radius_m: float = ROBOT_RADIUS_M,
    person_radius_m: float = 0.22,
    dpi: int = 110,
    furniture: Sequence = (),
    boxes: Mapping[str, object] | None = None,
) -> Path | None:
    """One panel per incident (up to 12): the walls, the furniture (footprints, kinds
    labelled: the map does not hold them, the contact often names them), the robot's true
    track (its footprint at the contact), each person's track (always those the contact
    names), arrows for the commanded direction.

    ``furniture`` / ``boxes``: every piece, fault-placed ones included, where it stands
    now (:func:`footprints`); an incident that kept its own copy
    (:meth:`FlightRecorder.on_events`) is drawn with that. A panel whose contact names a
    body it does not draw says so in its title, and a ``RuntimeWarning`` is raised."""
    if not incidents:
        return None
    now = footprints(furniture, boxes)
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    shown = incidents[:_MAX_PANELS]
    cols = min(3, len(shown))
    rows = int(math.ceil(len(shown) / cols))
    fig = Figure(figsize=(4.2 * cols, 4.2 * rows))
    FigureCanvasAgg(fig)
    segs = np.asarray(walls, dtype=np.float64).reshape(-1, 4)
    for k, inc in enumerate(shown):
        ax = fig.add_subplot(rows, cols, k + 1)
        pieces = inc.get("furniture", now)
        _draw_furniture(ax, pieces)
        missing = undrawn_bodies(inc, pieces)
        _draw_incident(ax, inc, segs, robot_radius_m, person_radius_m, missing)
        if missing:
            warnings.warn(f"incident figure: the contact at t={inc['event']['t']} s names {', '.join(missing)}, not drawn", RuntimeWarning, stacklevel=2)
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, dpi=dpi)
    return out


def _draw_incident(ax, inc: dict, segs: np.ndarray, robot_radius_m: float, person_radius_m: float, missing: Sequence[str] = ()) -> None:
    """One incident's panel, centred on the contact; ``missing``: bodies the contact
    names that are not drawn (said in the title)."""
    from matplotlib.collections import LineCollection

    ev, tr = inc["event"], inc["trace"]
    cx, cy = float(ev["x"]), float(ev["y"])
    ax.add_collection(LineCollection(segs.reshape(-1, 2, 2), colors="k", linewidths=1.2))
    if tr:
        named = {j for j in (person_index(b) for b in ev.get("bodies", [])) if j is not None}
        _draw_tracks(ax, tr, cx, cy, person_radius_m, named)
        _draw_commands(ax, tr)
    _draw_contact(ax, ev, cx, cy, robot_radius_m)
    ax.set_xlim(cx - _VIEW_HALF_M, cx + _VIEW_HALF_M)
    ax.set_ylim(cy - _VIEW_HALF_M, cy + _VIEW_HALF_M)
    ax.set_aspect("equal")
    seen = ev.get("person_in_view_s_ago")
    ax.set_title(
        f"t={ev['t']:.0f}s {','.join(ev.get('bodies', []))} {ev.get('nav_state', '')}"
        + (f"\nseen {seen:.1f}s ago" if seen is not None else "")
        + (f"\nNOT DRAWN: {', '.join(missing)}" if missing else ""),
        fontsize=8,
        color="red" if missing else "black",
    )
    ax.tick_params(labelsize=7)


def _draw_furniture(ax, furniture: Sequence) -> None:
    """Each piece's footprint (a rotated rectangle) and its label, kind and index as the
    contact events name them (``furniture_<i>``). ``furniture``: pieces as
    :func:`footprints` takes them, or its footprints."""
    from matplotlib.patches import Polygon

    pieces = furniture if all(isinstance(f, dict) for f in furniture) else footprints(furniture)
    for f in pieces:
        x, y, yaw = f["x"], f["y"], f["yaw"]
        lx, ly = f["size"]
        corners = rectangle_corners(x, y, yaw, lx, ly)
        ax.add_patch(Polygon(corners, closed=True, fill=True, facecolor=_FURNITURE_COLOR, edgecolor="saddlebrown", lw=1.0, alpha=0.6))
        ax.text(x, y, f["label"], fontsize=6, ha="center", va="center", clip_on=True)


def _draw_tracks(ax, tr: list[dict], cx: float, cy: float, person_radius_m: float, named: Collection[int] = ()) -> None:
    """The robot's true and estimated tracks, and the tracks of the people who came near
    the contact or whom it names (``named``: their indices), each with its body at the end."""
    from matplotlib.patches import Circle

    xy = np.array([f["truth"][:2] for f in tr])
    ax.plot(xy[:, 0], xy[:, 1], "-", color=_ROBOT_COLOR, lw=1.5, label="robot")
    est = np.array([f["estimate"][:2] for f in tr])
    ax.plot(est[:, 0], est[:, 1], ":", color=_ROBOT_COLOR, lw=1.0, label="estimate")
    ppl = np.array([f["people"] for f in tr if f["people"]])
    if not ppl.size:
        return
    for j in range(ppl.shape[1]):
        if j in named or np.min(np.hypot(ppl[:, j, 0] - cx, ppl[:, j, 1] - cy)) < _PERSON_NEAR_M:
            ax.plot(ppl[:, j, 0], ppl[:, j, 1], "-", color=_PERSON_COLOR, lw=1.0)
            ax.add_patch(Circle((ppl[-1, j, 0], ppl[-1, j, 1]), person_radius_m, fill=False, color=_PERSON_COLOR, lw=1.2))
            ax.text(ppl[-1, j, 0], ppl[-1, j, 1], f" p{j}", fontsize=7, color=_PERSON_COLOR, clip_on=True)


def _draw_commands(ax, tr: list[dict]) -> None:
    """Arrows for the commanded velocity (in world axes) at about a dozen frames."""
    for f in tr[:: max(1, len(tr) // 12)]:
        th = f["truth"][2]
        vx, vy = f["cmd"][0], f["cmd"][1]
        wx, wy = math.cos(th) * vx - math.sin(th) * vy, math.sin(th) * vx + math.cos(th) * vy
        ax.arrow(f["truth"][0], f["truth"][1], wx, wy, width=0.01, color=_COMMAND_COLOR, length_includes_head=True)


def _draw_contact(ax, ev: dict, cx: float, cy: float, robot_radius_m: float) -> None:
    """The robot's footprint and heading at the contact, a cross where it was touched."""
    from matplotlib.patches import Circle

    ax.add_patch(Circle((cx, cy), robot_radius_m, fill=False, color=_ROBOT_COLOR, lw=1.5))
    h = math.radians(ev.get("heading_deg", 0.0))
    ax.plot([cx, cx + robot_radius_m * math.cos(h)], [cy, cy + robot_radius_m * math.sin(h)], color=_ROBOT_COLOR)
    b = ev.get("bearing_deg")
    if b is not None and math.isfinite(b):
        a = h + math.radians(b)
        ax.plot(cx + robot_radius_m * math.cos(a), cy + robot_radius_m * math.sin(a), "x", color="k", ms=8)
