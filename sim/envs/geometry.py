"""Geometry for the gymnasium env (:mod:`sim.envs.depthnav`): geodesic goal distance and a KC scan.

- Geodesic distance to the goal (the progress reward's potential): a multi-source
  Dijkstra over the navigation graph from the nodes that see the goal, then, per step,
  the shortest ``|p - n_i| + D_i`` over the nodes (and the goal itself) that the robot
  sees within a radius. "Sees" is a straight line that crosses no wall. Where nothing
  is visible (a robot pressed into a corner), the nearest node is used regardless.
- A Kinect-Complete (KC) style laser scan (BV2012, VI-A): every valid pixel of the
  depth image back-projected to the robot frame, points within a height band
  down-projected to the floor, and the nearest one per azimuth bin over the camera's
  horizontal field of view, measured from the camera's floor position.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from autonomy.common.geometry import segments_cross_nb
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.planner import adjacency, dijkstra
from autonomy.perception.camera import CameraIntrinsics, CameraMount, pixel_rays


@numba.njit(cache=True, inline="always")
def _blocked(ax, ay, bx, by, walls, idx, n_idx):  # pragma: no cover - numba
    """True when segment a-b properly crosses one of the walls ``walls[idx[:n_idx]]``."""
    for k in range(n_idx):
        j = idx[k]
        if segments_cross_nb(ax, ay, bx, by, walls[j, 0], walls[j, 1], walls[j, 2], walls[j, 3]):
            return True
    return False


@numba.njit(cache=True)
def _walls_near(px, py, walls, radius, out):  # pragma: no cover - numba
    """Indices of the walls whose bounding box meets the square of half side ``radius``."""
    n = 0
    for j in range(walls.shape[0]):
        x0, x1 = min(walls[j, 0], walls[j, 2]), max(walls[j, 0], walls[j, 2])
        y0, y1 = min(walls[j, 1], walls[j, 3]), max(walls[j, 1], walls[j, 3])
        if x1 >= px - radius and x0 <= px + radius and y1 >= py - radius and y0 <= py + radius:
            out[n] = j
            n += 1
    return n


@numba.njit(cache=True)
def visible_points(px, py, pts, walls, radius):  # pragma: no cover - numba
    """Boolean mask of the points within ``radius`` of (px, py) with a clear line to it."""
    idx = np.empty(walls.shape[0], dtype=np.int64)
    n_idx = _walls_near(px, py, walls, radius, idx)
    out = np.zeros(pts.shape[0], dtype=np.bool_)
    r2 = radius * radius
    for i in range(pts.shape[0]):
        dx, dy = pts[i, 0] - px, pts[i, 1] - py
        if dx * dx + dy * dy <= r2 and not _blocked(px, py, pts[i, 0], pts[i, 1], walls, idx, n_idx):
            out[i] = True
    return out


@numba.njit(cache=True)
def _potential(px, py, pts, dist, walls, radius):  # pragma: no cover - numba
    """min_i |p - pts_i| + dist_i over the visible points; (value, index, visible)."""
    idx = np.empty(walls.shape[0], dtype=np.int64)
    n_idx = _walls_near(px, py, walls, radius, idx)
    best, best_i = np.inf, -1
    near, near_i = np.inf, -1
    r2 = radius * radius
    for i in range(pts.shape[0]):
        di = dist[i]
        if not np.isfinite(di):
            continue
        dx, dy = pts[i, 0] - px, pts[i, 1] - py
        d2 = dx * dx + dy * dy
        e = math.sqrt(d2)
        if e + di < near:
            near, near_i = e + di, i
        if d2 > r2 or e + di >= best:
            continue
        if not _blocked(px, py, pts[i, 0], pts[i, 1], walls, idx, n_idx):
            best, best_i = e + di, i
    if best_i < 0:
        return near, near_i, False
    return best, best_i, True


class GeodesicField:
    """Shortest drivable distance to one goal over a navigation graph (see module doc).

    ``points`` holds the graph's nodes followed by the goal itself (distance 0), so a goal
    in plain sight is measured straight.
    """

    def __init__(self, graph: NavGraph, walls: np.ndarray, goal_xy: np.ndarray, radius_m: float) -> None:
        self.radius_m = float(radius_m)
        self.walls = np.ascontiguousarray(walls, dtype=np.float64).reshape(-1, 4)
        self.goal = np.asarray(goal_xy, dtype=np.float64).reshape(2).copy()
        xy = graph.node_xy()
        n = len(xy)
        adj = adjacency(graph)
        vis = visible_points(self.goal[0], self.goal[1], xy, self.walls, self.radius_m) if n else np.zeros(0, bool)
        d0 = np.hypot(xy[:, 0] - self.goal[0], xy[:, 1] - self.goal[1]) if n else np.zeros(0)
        if n and not vis.any():
            vis[int(np.argmin(d0))] = True
        # From every node that sees the goal, starting at its straight-line distance;
        # parent -1: the next stop is the goal itself.
        dist, parent = dijkstra(adj, {int(i): float(d0[i]) for i in np.flatnonzero(vis)})
        self.node_dist = dist
        self.parent = parent
        self.points = np.ascontiguousarray(np.vstack([xy.reshape(-1, 2), self.goal[None, :]]))
        self._dist = np.append(dist, 0.0)

    def distance(self, xy: np.ndarray) -> tuple[float, int]:
        """(geodesic distance, index of the first stop: a node, or ``len(nodes)`` for the goal)."""
        d, i, _ = _potential(float(xy[0]), float(xy[1]), self.points, self._dist, self.walls, self.radius_m)
        return float(d), int(i)

    def path(self, xy: np.ndarray) -> np.ndarray:
        """(k, 2) polyline from ``xy`` along the shortest route to the goal."""
        _, i = self.distance(xy)
        pts = [np.asarray(xy[:2], dtype=np.float64)]
        n_nodes = len(self.node_dist)
        guard = 0
        while 0 <= i < n_nodes and guard <= n_nodes:
            pts.append(self.points[i])
            i = int(self.parent[i])
            guard += 1
        pts.append(self.goal)
        return np.array(pts)


# --------------------------------------------------------------------------- KC scan


@numba.njit(cache=True)
def _kc_scan(depth, rays, tx, ty, tz, ox, oy, zmin, zmax, a0, inv_da, rmax, out):  # pragma: no cover
    nb = out.shape[0]
    for b in range(nb):
        out[b] = 0.0
    h, w = depth.shape
    for v in range(h):
        for u in range(w):
            z = depth[v, u]
            if z <= 0.0:
                continue
            pz = tz + z * rays[v, u, 2]
            if pz < zmin or pz > zmax:
                continue
            dx = tx + z * rays[v, u, 0] - ox
            dy = ty + z * rays[v, u, 1] - oy
            b = int(math.floor((math.atan2(dy, dx) - a0) * inv_da))
            if b < 0 or b >= nb:
                continue
            r = min(math.sqrt(dx * dx + dy * dy), rmax)
            if out[b] == 0.0 or r < out[b]:
                out[b] = r


class KCScanner:
    """A KC-style simulated laser scan from a depth image (see the module doc).

    Bins split ``[-fov_h / 2, fov_h / 2]`` about the robot's x axis evenly; bin 0 is the
    rightmost (most negative azimuth). Empty bins are 0.
    """

    def __init__(
        self,
        intr: CameraIntrinsics,
        mount: CameraMount,
        n_bins: int,
        min_height_m: float,
        max_height_m: float,
        max_depth_m: float,
    ) -> None:
        rot = mount.rotation()
        self.rays = np.ascontiguousarray(pixel_rays(intr) @ rot.T)
        self.t = mount.translation()
        self.n_bins = int(n_bins)
        self.fov = intr.fov_h_rad
        self.a0 = -self.fov / 2
        self.inv_da = self.n_bins / self.fov
        self.zmin, self.zmax = float(min_height_m), float(max_height_m)
        #: The longest horizontal range a pixel of depth max_depth_m can give.
        self.max_range_m = float(max_depth_m * np.hypot(self.rays[..., 0], self.rays[..., 1]).max())

    @property
    def angles(self) -> np.ndarray:
        """Centre azimuth of each bin (robot frame, radians)."""
        return self.a0 + (np.arange(self.n_bins) + 0.5) / self.inv_da

    def scan(self, depth: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Ranges (float32, metres, 0 = no return) from a planar depth image."""
        if out is None:
            out = np.empty(self.n_bins, dtype=np.float32)
        t = self.t
        _kc_scan(
            np.ascontiguousarray(depth, dtype=np.float32), self.rays, t[0], t[1], t[2], t[0], t[1],
            self.zmin, self.zmax, self.a0, self.inv_da, self.max_range_m, out,
        )
        return out
