"""The navigator's obstacle memory, one numba pass a frame.

Obstacle points are kept in the world frame on a grid of ``cell`` metres, one point per
cell with the latest time it was sensed. Each frame
(:meth:`autonomy.navigation.surroundings.Surroundings.remember`):

1. remembered points the camera sees now are dropped (the current frame replaces them),
   and so are those older than ``keep_s`` unless they lie right in front of the robot,
   closer than the camera can see, and are at most ``blind_s`` old, and those farther
   than ``keep_radius`` from it;
2. this frame's points within ``sense_radius`` join, a new cell taking the current time,
   and so does each one's shadow: the cells every ``cell`` behind it along the camera's
   sight line, up to ``shadow_depth`` beyond it. The camera sees only an obstacle's near
   faces; what stands behind them is unknown, and is taken as occupied until the camera
   looks there (then step 1 replaces it with what it sees). A shadow ends at the map's
   walls (``walls``: points along them, on the grid with the cells round each): behind
   a wall the camera sees at a grazing angle lies the room beyond, whose door the robot
   may be about to pass, and a wall's own points cast none;
3. the memory is returned in the robot frame, with the mask of what the avoidance uses
   (seen within ``memory_s``; seen within ``beside_s`` and no farther than
   ``beside_radius`` from the robot; or in the blind zone ahead and seen within
   ``blind_s``).

Everything kept lies within ``keep_radius`` of the robot, so the cells are merged on a
dense local grid around it rather than by sorting a frame's few thousand sensed points;
the grid is read in order of (x cell, y cell), the order ``np.unique`` gives, so the
result is the numpy reference's (tests/autonomy/test_obstacle_memory.py). One kernel
does what would otherwise be about 30 numpy calls a frame, each with its call overhead.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _in_view(bx: float, by: float, half_fov: float, r_min: float, r_max: float) -> bool:  # pragma: no cover - numba
    r = math.hypot(bx, by)
    return abs(math.atan2(by, bx)) < half_fov and r > r_min and r < r_max


@numba.njit(cache=True, inline="always")
def _blind_ahead(bx: float, by: float, forward: float, blind_range: float, blind_half_width: float) -> bool:  # pragma: no cover
    return bx > -forward and math.hypot(bx, by) <= blind_range and abs(by) < blind_half_width


@numba.njit(cache=True, inline="always")
def _grid_index(wx: float, wy: float, cell: float, cx0: int, cy0: int, side: int) -> int:  # pragma: no cover - numba
    """Flat index of the cell of world point (wx, wy) on the local grid; -1 off the grid
    (never for finite input within keep_radius; a non-finite pose lands here)."""
    ix = np.int64(np.rint(wx / cell)) - cx0
    iy = np.int64(np.rint(wy / cell)) - cy0
    if ix < 0 or ix >= side or iy < 0 or iy >= side:
        return -1
    return ix * side + iy


@numba.njit(cache=True)
def update_memory(
    mem: np.ndarray,
    mem_t: np.ndarray,
    obs: np.ndarray,
    x: float,
    y: float,
    yaw: float,
    t: float,
    cell: float,
    keep_s: float,
    memory_s: float,
    keep_radius: float,
    sense_radius: float,
    forward: float,
    view_half_fov: float,
    view_r_min: float,
    view_r_max: float,
    blind_range: float,
    blind_half_width: float,
    beside_s: float,
    beside_radius: float,
    blind_s: float,
    shadow_depth: float,
    walls: np.ndarray,
    wall_reach: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """One frame of the memory (steps 1-3 above).

    ``mem`` (n, 2) world points on the grid and ``mem_t`` their times; ``obs`` (m, 2)
    this frame's obstacles in the robot frame. ``view_*`` describe the region whose
    remembered points are replaced (camera-relative, robot axes); ``blind_*`` the blind
    zone ahead. Returns the new ``mem``, ``mem_t``, all of it in the robot frame, and
    the avoidance's mask. ``sense_radius`` must not exceed ``keep_radius``, nor
    ``beside_s`` ``keep_s``. The camera's sight lines start at (``forward``, 0), robot
    frame; ``shadow_depth`` 0 casts no shadows; ``walls`` (k, 2) are world points along
    the map's walls, each marking the cells within ``wall_reach`` cells of its own (at
    least the points' spacing, so that the marks join up).
    """
    c, s = math.cos(yaw), math.sin(yaw)
    # The local grid: every cell within keep_radius of the robot's own cell.
    half = int(math.ceil(keep_radius / cell)) + 1
    side = 2 * half + 1
    cx0 = np.int64(np.rint(x / cell)) - half
    cy0 = np.int64(np.rint(y / cell)) - half
    when = np.full(side * side, -np.inf)  # -inf: empty
    # Where shadows end: the cells round each wall point, at least a cell either side, so
    # that a sight line stepping a cell at a time cannot slip between two of them.
    wall = np.zeros(side * side, dtype=np.bool_)
    if shadow_depth > 0.0:
        for i in range(walls.shape[0]):
            ix = np.int64(np.rint(walls[i, 0] / cell)) - cx0
            iy = np.int64(np.rint(walls[i, 1] / cell)) - cy0
            for jx in range(max(ix - wall_reach, 0), min(ix + wall_reach + 1, side)):
                for jy in range(max(iy - wall_reach, 0), min(iy + wall_reach + 1, side)):
                    wall[jx * side + jy] = True
    n = 0
    for i in range(mem.shape[0]):
        rx, ry = mem[i, 0] - x, mem[i, 1] - y
        bx = c * rx + s * ry - forward
        by = -s * rx + c * ry
        if _in_view(bx, by, view_half_fov, view_r_min, view_r_max):
            continue
        if not math.hypot(rx, ry) <= keep_radius:
            continue
        age = t - mem_t[i]
        if age > keep_s and not (age <= blind_s and _blind_ahead(bx, by, forward, blind_range, blind_half_width)):
            continue
        k = _grid_index(mem[i, 0], mem[i, 1], cell, cx0, cy0, side)
        if k < 0:
            continue
        if when[k] == -np.inf:
            n += 1
        when[k] = mem_t[i]
    # This frame's points take the current time, over what was remembered there.
    for i in range(obs.shape[0]):
        ox, oy = obs[i, 0], obs[i, 1]
        if not math.hypot(ox, oy) <= sense_radius:  # NaN points are dropped too
            continue
        wx = c * ox - s * oy + x
        wy = s * ox + c * oy + y
        k = _grid_index(wx, wy, cell, cx0, cy0, side)
        if k < 0:
            continue
        if when[k] == -np.inf:
            n += 1
        when[k] = t
        # The shadow: cells every `cell` behind the point along the camera's sight line.
        dx, dy = ox - forward, oy
        r = math.hypot(dx, dy)
        if shadow_depth <= 0.0 or r <= 0.0:
            continue
        ux, uy = dx / r, dy / r
        for j in range(1, int(math.floor(shadow_depth / cell + 1e-9)) + 1):
            sx, sy = ox + j * cell * ux, oy + j * cell * uy
            if not math.hypot(sx, sy) <= keep_radius:
                break
            k = _grid_index(c * sx - s * sy + x, s * sx + c * sy + y, cell, cx0, cy0, side)
            if k < 0 or wall[k]:
                break
            if when[k] == -np.inf:
                n += 1
            when[k] = t
    new_mem = np.empty((n, 2))
    new_t = np.empty(n)
    rel = np.empty((n, 2))
    recent = np.empty(n, dtype=np.bool_)
    m = 0
    for k in range(side * side):
        if when[k] == -np.inf:
            continue
        wx, wy = (cx0 + k // side) * cell, (cy0 + k % side) * cell
        new_mem[m, 0], new_mem[m, 1] = wx, wy
        new_t[m] = when[k]
        rx, ry = wx - x, wy - y
        ux, uy = c * rx + s * ry, -s * rx + c * ry
        rel[m, 0], rel[m, 1] = ux, uy
        age = t - when[k]
        recent[m] = (
            age <= memory_s
            or (age <= beside_s and math.hypot(ux, uy) <= beside_radius)
            or (age <= blind_s and _blind_ahead(ux - forward, uy, forward, blind_range, blind_half_width))
        )
        m += 1
    return new_mem, new_t, rel, recent
