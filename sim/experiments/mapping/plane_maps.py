"""Experiment III's plane maps judged and drawn: how far their walls lie from the true
walls, and the top view of each map over the true walls and both trajectories."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from autonomy.common.geometry import point_segment_distance
from autonomy.planes import PlaneOctree


def map_wall_error(tree: PlaneOctree, segs: np.ndarray) -> float:
    """Median distance (m) of the map's wall planes (normal within 30 degrees of horizontal) to the nearest true wall."""
    d = [
        float(np.min(point_segment_distance(np.asarray(p.centroid[:2]), segs)))
        for p in tree.planes()
        if abs(p.normal[2]) < math.sin(math.radians(30.0))
    ]
    return float(np.median(d)) if d else float("nan")


def draw_maps(path: Path, maps: dict[str, PlaneOctree], segs: np.ndarray, truth: np.ndarray, odom: np.ndarray, title: str) -> Path:
    """Top view PNG: true walls, trajectories and each map's plane patches (one panel a map)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.figure import Figure

    cols = min(len(maps), 2)
    rows = -(-len(maps) // cols)
    fig = Figure(figsize=(6.5 * cols, 5.0 * rows))
    FigureCanvasAgg(fig)
    for k, (name, tree) in enumerate(maps.items()):
        ax = fig.add_subplot(rows, cols, k + 1)
        ax.add_collection(LineCollection(segs.reshape(-1, 2, 2), colors="#bbbbbb", linewidths=2.0, label="true walls"))
        lines, colors, polys = [], [], []
        for lf in tree.leaves():
            p = lf.entry.plane
            if len(p.hull) < 2:
                continue
            if abs(p.normal[2]) < 0.5:  # a wall: its footprint, the hull's extent along the wall
                t = np.array([-p.normal[1], p.normal[0]])
                t /= np.linalg.norm(t)
                s = p.hull[:, :2] @ t
                base = p.centroid[:2] - (p.centroid[:2] @ t) * t
                lines.append([base + s.min() * t, base + s.max() * t])
                colors.append("#08306b")
            else:
                polys.append(p.hull[:, :2])
        if polys:
            ax.add_collection(PolyCollection(polys, facecolors="#9ecae1", edgecolors="none", alpha=0.4))
        if lines:
            ax.add_collection(LineCollection(lines, colors=colors, linewidths=1.2, label="wall planes"))
        ax.plot(truth[:, 0], truth[:, 1], "-", color="#2ca02c", lw=0.8, label="true path")
        ax.plot(odom[:, 0], odom[:, 1], "--", color="#d62728", lw=0.8, label="odometry")
        ax.set_aspect("equal")
        ax.autoscale()
        ax.set_title(f"{name}: {tree.n_leaves} planes")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.legend(loc="upper right", fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path
