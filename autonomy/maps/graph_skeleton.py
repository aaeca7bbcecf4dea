"""The skeleton of the free space and its branches (steps 2 and 3 of
:mod:`autonomy.maps.graph_builder`).

The cells at least ``robot radius + margin`` from every wall are thinned to a one-cell
skeleton (Zhang and Suen, "A fast parallel algorithm for thinning digital patterns", CACM
1984), which runs along corridor centre lines, through doorways into rooms and between
pillars, and keeps the free space's topology (one piece per region). The skeleton is
traced into branches between junctions and ends; dead-end spurs that end within the
junction's clearance plus ``spur_m`` (towards room corners, wall irregularities) are pruned.
"""

from __future__ import annotations

import numba
import numpy as np

from autonomy.maps.freespace import FreeSpace
from autonomy.maps.graph_config import GraphBuildConfig

__all__ = ["thin"]


@numba.njit(cache=True)
def _zs_deletable(img: np.ndarray, y: int, x: int, sub: int) -> bool:  # pragma: no cover - numba
    p2 = img[y + 1, x]
    p3 = img[y + 1, x + 1]
    p4 = img[y, x + 1]
    p5 = img[y - 1, x + 1]
    p6 = img[y - 1, x]
    p7 = img[y - 1, x - 1]
    p8 = img[y, x - 1]
    p9 = img[y + 1, x - 1]
    b = p2 + p3 + p4 + p5 + p6 + p7 + p8 + p9
    if b < 2 or b > 6:
        return False
    a = ((p2 == 0) & (p3 == 1)) + ((p3 == 0) & (p4 == 1)) + ((p4 == 0) & (p5 == 1)) + ((p5 == 0) & (p6 == 1)) \
        + ((p6 == 0) & (p7 == 1)) + ((p7 == 0) & (p8 == 1)) + ((p8 == 0) & (p9 == 1)) + ((p9 == 0) & (p2 == 1))
    if a != 1:
        return False
    if sub == 0:
        return p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0
    return p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0


@numba.njit(cache=True)
def thin(mask: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Zhang-Suen thinning of a boolean image (border cells count as background); only
    contour cells are revisited, so the cost follows the contour, not the image."""
    ny, nx = mask.shape
    img = np.zeros((ny, nx), dtype=np.uint8)
    for y in range(1, ny - 1):
        for x in range(1, nx - 1):
            if mask[y, x]:
                img[y, x] = 1
    stamp = np.zeros(ny * nx, dtype=np.int32)
    cand = []
    for y in range(1, ny - 1):
        for x in range(1, nx - 1):
            if img[y, x] and (img[y + 1, x] == 0 or img[y - 1, x] == 0 or img[y, x + 1] == 0 or img[y, x - 1] == 0
                              or img[y + 1, x + 1] == 0 or img[y - 1, x - 1] == 0 or img[y + 1, x - 1] == 0 or img[y - 1, x + 1] == 0):
                cand.append(y * nx + x)
    tick = 0
    while True:
        changed = False
        for sub in range(2):
            dele = []
            for c in cand:
                y, x = c // nx, c % nx
                if img[y, x] and _zs_deletable(img, y, x, sub):
                    dele.append(c)
            for c in dele:
                img[c // nx, c % nx] = 0
            if len(dele):
                changed = True
            tick += 1
            nxt = []
            for c in cand:
                if img[c // nx, c % nx] and stamp[c] != tick:
                    stamp[c] = tick
                    nxt.append(c)
            for c in dele:
                y, x = c // nx, c % nx
                for dy in range(-1, 2):
                    for dx in range(-1, 2):
                        yy, xx = y + dy, x + dx
                        if 0 < yy < ny - 1 and 0 < xx < nx - 1 and img[yy, xx]:
                            q = yy * nx + xx
                            if stamp[q] != tick:
                                stamp[q] = tick
                                nxt.append(q)
            cand = nxt
        if not changed:
            break
    return img.astype(np.bool_)


@numba.njit(cache=True)
def _trace(skel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Branches of a skeleton between key cells (ends, junctions; one cell per key-free
    loop). Returns (cluster of each cell, -1 if none), branch start / end cluster, branch
    cell offsets and the flat cell indices of every branch, ends included."""
    ny, nx = skel.shape
    nb = np.zeros((ny, nx), dtype=np.int8)
    for y in range(1, ny - 1):
        for x in range(1, nx - 1):
            if skel[y, x]:
                s = 0
                for dy in range(-1, 2):
                    for dx in range(-1, 2):
                        if (dy or dx) and skel[y + dy, x + dx]:
                            s += 1
                nb[y, x] = s
    key = np.zeros((ny, nx), dtype=np.bool_)
    for y in range(ny):
        for x in range(nx):
            key[y, x] = skel[y, x] and nb[y, x] != 2
    # 8-connected clusters of key cells
    clus = np.full((ny, nx), -1, dtype=np.int32)
    stack = np.empty(ny * nx, dtype=np.int64)
    n_clus = 0
    for y0 in range(ny):
        for x0 in range(nx):
            if key[y0, x0] and clus[y0, x0] < 0:
                top = 0
                stack[0] = y0 * nx + x0
                clus[y0, x0] = n_clus
                while top >= 0:
                    c = stack[top]
                    top -= 1
                    y, x = c // nx, c % nx
                    for dy in range(-1, 2):
                        for dx in range(-1, 2):
                            yy, xx = y + dy, x + dx
                            if 0 <= yy < ny and 0 <= xx < nx and key[yy, xx] and clus[yy, xx] < 0:
                                clus[yy, xx] = n_clus
                                top += 1
                                stack[top] = yy * nx + xx
                n_clus += 1
    visited = np.zeros((ny, nx), dtype=np.bool_)
    b0 = []
    b1 = []
    offs = [0]
    cells = []
    for phase in range(2):
        for y0 in range(1, ny - 1):
            for x0 in range(1, nx - 1):
                if phase == 1 and skel[y0, x0] and not key[y0, x0] and not visited[y0, x0]:
                    key[y0, x0] = True  # a loop with no key cell: cut it here
                    clus[y0, x0] = n_clus
                    n_clus += 1
                if not key[y0, x0]:
                    continue
                if phase == 1 and clus[y0, x0] != n_clus - 1:
                    continue
                for dy in range(-1, 2):
                    for dx in range(-1, 2):
                        y, x = y0 + dy, x0 + dx
                        if (dy == 0 and dx == 0) or not skel[y, x] or key[y, x] or visited[y, x]:
                            continue
                        path = [y0 * nx + x0, y * nx + x]
                        visited[y, x] = True
                        py, px = y0, x0
                        end = -1
                        while True:
                            ny_, nx_ = -1, -1
                            for ey in range(-1, 2):
                                for ex in range(-1, 2):
                                    yy, xx = y + ey, x + ex
                                    if (ey == 0 and ex == 0) or (yy == py and xx == px) or not skel[yy, xx]:
                                        continue
                                    if key[yy, xx]:
                                        if ny_ < 0 or not key[ny_, nx_]:
                                            ny_, nx_ = yy, xx
                                    elif not visited[yy, xx] and ny_ < 0:
                                        ny_, nx_ = yy, xx
                            if ny_ < 0:
                                break
                            path.append(ny_ * nx + nx_)
                            if key[ny_, nx_]:
                                end = clus[ny_, nx_]
                                break
                            visited[ny_, nx_] = True
                            py, px, y, x = y, x, ny_, nx_
                        if end >= 0:
                            b0.append(clus[y0, x0])
                            b1.append(end)
                            for c in path:
                                cells.append(c)
                            offs.append(len(cells))
    n = len(b0)
    a0 = np.empty(n, dtype=np.int64)
    a1 = np.empty(n, dtype=np.int64)
    for i in range(n):
        a0[i] = b0[i]
        a1[i] = b1[i]
    o = np.empty(len(offs), dtype=np.int64)
    for i in range(len(offs)):
        o[i] = offs[i]
    cl = np.empty(len(cells), dtype=np.int64)
    for i in range(len(cells)):
        cl[i] = cells[i]
    return clus, a0, a1, o, cl, np.array([n_clus], dtype=np.int64)


def _branches(skel: np.ndarray, fs: FreeSpace, cfg: GraphBuildConfig) -> tuple[dict[int, np.ndarray], list[tuple[int, int, np.ndarray]]]:
    """Skeleton branches as (start cluster, end cluster, cell indices), spurs pruned and
    degree-2 clusters merged; and each kept cluster's representative cell."""
    clus, b0, b1, offs, cells, ncl = _trace(skel)
    n_clus = int(ncl[0])
    nx = fs.shape[1]
    flat_dist = fs.dist.ravel()
    # Representative cell of a cluster: its cell farthest from the walls.
    rows, cols = np.nonzero(clus >= 0)
    flat = rows * nx + cols
    cid = clus[rows, cols]
    order = np.lexsort((-flat_dist[flat], cid))
    first = np.ones(order.size, dtype=bool)
    first[1:] = cid[order][1:] != cid[order][:-1]
    rep = {int(c): int(f) for c, f in zip(cid[order][first], flat[order][first], strict=True)}
    branches: dict[int, tuple[int, int, np.ndarray]] = {}
    adj: dict[int, set[int]] = {c: set() for c in range(n_clus)}
    for k in range(b0.size):
        u, v = int(b0[k]), int(b1[k])
        if u == v and offs[k + 1] - offs[k] <= 3:
            continue
        branches[k] = (u, v, cells[offs[k] : offs[k + 1]])
        adj[u].add(k)
        adj[v].add(k)

    def xy(c: int) -> np.ndarray:
        f = rep[c]
        return fs.centres(np.array(f // nx), np.array(f % nx))

    def clearance(c: int) -> float:
        return float(flat_dist[rep[c]])

    # Prune spurs: dead ends that stay within their junction's clearance plus spur_m.
    changed = True
    while changed:
        changed = False
        for v in range(n_clus):
            deg = len(adj[v])
            if deg < 3:
                continue
            spurs = []
            for k in adj[v]:
                a, b, _ = branches[k]
                u = b if a == v else a
                if (u != v and len(adj[u]) == 1 and clearance(u) < clearance(v) - cfg.tolerance_m
                        and np.hypot(*(xy(u) - xy(v))) <= clearance(v) + cfg.spur_m):
                    spurs.append((np.hypot(*(xy(u) - xy(v))), k, u))
            if not spurs:
                continue
            if len(spurs) == deg:  # a star of spurs only: keep the longest
                spurs.sort()
                spurs = spurs[:-1]
            for _, k, u in spurs:
                adj[v].discard(k)
                adj[u].discard(k)
                del branches[k]
            changed = True
    # Merge branches through clusters of degree 2 (staircase cells, pruned junctions).
    for v in range(n_clus):
        if len(adj[v]) != 2:
            continue
        k1, k2 = tuple(adj[v])
        if branches[k1][0] == branches[k1][1] or branches[k2][0] == branches[k2][1]:
            continue
        a1, c1, p1 = branches[k1]
        a2, c2, p2 = branches[k2]
        if a1 == v:
            a1, c1, p1 = c1, a1, p1[::-1]
        if c2 == v:
            a2, c2, p2 = c2, a2, p2[::-1]
        # p1 ends at v, p2 starts at v
        merged = (a1, c2, np.concatenate([p1, p2[1:]]))
        del branches[k1], branches[k2]
        adj[v].clear()
        adj[a1].discard(k1)
        adj[c2].discard(k2)
        branches[k1] = merged
        adj[a1].add(k1)
        adj[c2].add(k1)
    used = {c for a, b, _ in branches.values() for c in (a, b)}
    reps = {c: xy(c) for c in used}
    out = []
    for a, b, p in branches.values():
        # the cluster's representative, then the branch's own cells (its end cells are in
        # the clusters): the step from the representative is then within the cluster
        pts = np.concatenate([reps[a][None], fs.centres(p // nx, p % nx), reps[b][None]])
        out.append((a, b, pts))
    return reps, out

