"""Free space of a vector map: where a robot of a given radius can be, inside the building,
split into connected regions.

The walls are rasterised onto a square grid of ``cell_m`` cells (every cell a wall passes
through is marked), and an exact Euclidean distance transform (Felzenszwalb and
Huttenlocher, "Distance Transforms of Sampled Functions", 2012) gives each cell centre its
distance to the nearest wall cell centre. That grid distance differs from the exact
distance to the walls by at most :attr:`FreeSpace.error_m` (half a cell diagonal plus the
rasteriser's sampling step), so every threshold here subtracts it: a cell called free
for clearance ``c`` is at least ``c`` from every wall.

Inside and outside: the free cells connected to the grid's padded border are the outside
of the building, unless the building leaks (a gap in an exterior wall, common in mapped
buildings): then a cell on that border-connected space still counts as inside when walls
stop nearly all of ``enclosure_rays`` rays cast from it (a point outside a building sees
open space over at least a quarter turn, except in a courtyard). Regions smaller than
``min_region_area_m2`` (gaps in double walls, pillar interiors) are voids, not regions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from autonomy.constants import ROBOT_RADIUS_M
from autonomy.errors import InputError, require_int, require_positive
from autonomy.vectormap import VectorMap

__all__ = ["FreeSpaceConfig", "FreeSpace", "build_free_space", "rasterise", "grid_distance", "label_components", "MAX_GRID_CELLS"]

#: The largest grid :func:`build_free_space` makes (a 250 x 250 m floor at 5 cm cells).
MAX_GRID_CELLS = 25_000_000
_FAR = 1e20
_RASTER_STEP = 1.0 / 8.0  # rasteriser sample step, in cells


@dataclass(frozen=True)
class FreeSpaceConfig:
    """Grid and thresholds of the free-space analysis."""

    cell_m: float = 0.05
    """Grid cell size. The clearance error bound is about 0.77 of it."""
    robot_radius_m: float = ROBOT_RADIUS_M
    """The robot's footprint radius: a cell is free when at least this far from every wall."""
    padding_m: float = 1.5
    """Free margin added around the map's extent (the outside the border flood starts from)."""
    enclosure_rays: int = 16
    """Rays cast from a border-connected cell to decide whether it is inside a leaky building."""
    enclosure_max_escapes: int = 1
    """A border-connected cell is inside when at most this many of its rays leave the map."""
    min_region_area_m2: float = 1.0
    """Smaller connected free areas are voids (no region, no graph nodes)."""

    def __post_init__(self) -> None:
        require_positive(self, "free_space.", "cell_m", "robot_radius_m", "padding_m", "min_region_area_m2")
        require_int(self, "free_space.", "enclosure_rays", minimum=4)
        require_int(self, "free_space.", "enclosure_max_escapes", minimum=0)
        if self.padding_m < self.robot_radius_m + 2 * self.cell_m:
            raise InputError(
                f"free_space.padding_m: expected at least robot_radius_m + 2 cells "
                f"({self.robot_radius_m + 2 * self.cell_m:.3f} m), got {self.padding_m!r}"
            )

    @property
    def error_m(self) -> float:
        """Largest difference between a cell's grid distance and its exact wall distance."""
        return (math.sqrt(0.5) + 0.5 * _RASTER_STEP) * self.cell_m


# --------------------------------------------------------------------------- kernels


@numba.njit(cache=True)
def rasterise(seg: np.ndarray, x0: float, y0: float, cell: float, ny: int, nx: int) -> np.ndarray:  # pragma: no cover - numba
    """Mark every cell of a (ny, nx) grid with lower-left corner (x0, y0) that a segment
    passes through (samples every 1/8 cell along it)."""
    wall = np.zeros((ny, nx), dtype=np.bool_)
    step = _RASTER_STEP * cell
    for i in range(seg.shape[0]):
        ax, ay, bx, by = seg[i, 0], seg[i, 1], seg[i, 2], seg[i, 3]
        n = int(math.ceil(math.hypot(bx - ax, by - ay) / step)) + 1
        for k in range(n + 1):
            t = k / n
            cx = int((ax + t * (bx - ax) - x0) / cell)
            cy = int((ay + t * (by - ay) - y0) / cell)
            if 0 <= cx < nx and 0 <= cy < ny:
                wall[cy, cx] = True
    return wall


@numba.njit(cache=True)
def _edt_1d(f: np.ndarray, d: np.ndarray, v: np.ndarray, z: np.ndarray) -> None:  # pragma: no cover - numba
    """Squared distance transform of one row (Felzenszwalb and Huttenlocher, Algorithm 1)."""
    n = f.shape[0]
    k = 0
    v[0] = 0
    z[0] = -np.inf
    z[1] = np.inf
    for q in range(1, n):
        p = v[k]
        s = ((f[q] + q * q) - (f[p] + p * p)) / (2.0 * q - 2.0 * p)
        while s <= z[k]:
            k -= 1
            p = v[k]
            s = ((f[q] + q * q) - (f[p] + p * p)) / (2.0 * q - 2.0 * p)
        k += 1
        v[k] = q
        z[k] = s
        z[k + 1] = np.inf
    k = 0
    for q in range(n):
        while z[k + 1] < q:
            k += 1
        p = v[k]
        d[q] = (q - p) * (q - p) + f[p]


@numba.njit(cache=True)
def _edt(wall: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Squared Euclidean distance (in cells) from each cell centre to the nearest wall cell."""
    ny, nx = wall.shape
    m = max(nx, ny)
    out = np.empty((ny, nx), dtype=np.float64)
    f = np.empty(m, dtype=np.float64)
    d = np.empty(m, dtype=np.float64)
    v = np.empty(m, dtype=np.int64)
    z = np.empty(m + 1, dtype=np.float64)
    for x in range(nx):
        for y in range(ny):
            f[y] = 0.0 if wall[y, x] else _FAR
        _edt_1d(f[:ny], d[:ny], v, z)
        for y in range(ny):
            out[y, x] = d[y]
    for y in range(ny):
        for x in range(nx):
            f[x] = out[y, x]
        _edt_1d(f[:nx], d[:nx], v, z)
        for x in range(nx):
            out[y, x] = d[x]
    return out


@numba.njit(cache=True)
def label_components(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """4-connected components of ``mask``: (labels with -1 off the mask, cell count per label)."""
    ny, nx = mask.shape
    lab = np.full((ny, nx), -1, dtype=np.int32)
    stack = np.empty(ny * nx, dtype=np.int64)
    sizes = []
    n = 0
    for sy in range(ny):
        for sx in range(nx):
            if not mask[sy, sx] or lab[sy, sx] >= 0:
                continue
            top = 0
            stack[0] = sy * nx + sx
            lab[sy, sx] = n
            count = 0
            while top >= 0:
                c = stack[top]
                top -= 1
                count += 1
                y, x = c // nx, c % nx
                for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                    yy, xx = y + dy, x + dx
                    if 0 <= yy < ny and 0 <= xx < nx and mask[yy, xx] and lab[yy, xx] < 0:
                        lab[yy, xx] = n
                        top += 1
                        stack[top] = yy * nx + xx
            sizes.append(count)
            n += 1
    out = np.empty(n, dtype=np.int64)
    for i in range(n):
        out[i] = sizes[i]
    return lab, out


@numba.njit(cache=True)
def _ray_escapes(coarse: np.ndarray, cy: float, cx: float, n_rays: int) -> int:  # pragma: no cover - numba
    """How many of ``n_rays`` rays from (cy, cx) (coarse-cell units) leave the grid
    without meeting a wall cell."""
    ny, nx = coarse.shape
    esc = 0
    for r in range(n_rays):
        a = 2.0 * math.pi * r / n_rays
        dy, dx = 0.5 * math.sin(a), 0.5 * math.cos(a)
        y, x = cy, cx
        while True:
            y += dy
            x += dx
            iy, ix = int(math.floor(y)), int(math.floor(x))
            if iy < 0 or ix < 0 or iy >= ny or ix >= nx:
                esc += 1
                break
            if coarse[iy, ix]:
                break
    return esc


@numba.njit(cache=True)
def _enclosed(
    lab: np.ndarray, open_labels: np.ndarray, coarse: np.ndarray, k: int, n_rays: int, max_escapes: int
) -> np.ndarray:  # pragma: no cover - numba
    """Cells of the border-connected components that lie inside (judged per k x k block
    from the block's centre)."""
    ny, nx = lab.shape
    out = np.zeros((ny, nx), dtype=np.bool_)
    is_open = np.zeros(open_labels.max() + 1 if open_labels.size else 1, dtype=np.bool_)
    for lb in open_labels:
        is_open[lb] = True
    for by in range(0, ny, k):
        for bx in range(0, nx, k):
            any_open = False
            for y in range(by, min(by + k, ny)):
                for x in range(bx, min(bx + k, nx)):
                    lb = lab[y, x]
                    if lb >= 0 and lb < is_open.size and is_open[lb]:
                        any_open = True
            if not any_open:
                continue
            if _ray_escapes(coarse, by / k + 0.5, bx / k + 0.5, n_rays) > max_escapes:
                continue
            for y in range(by, min(by + k, ny)):
                for x in range(bx, min(bx + k, nx)):
                    lb = lab[y, x]
                    if lb >= 0 and lb < is_open.size and is_open[lb]:
                        out[y, x] = True
    return out


def grid_distance(cells: np.ndarray, cell_m: float) -> np.ndarray:
    """(ny, nx) float32 distance in metres from each cell centre to the nearest True cell."""
    return (np.sqrt(_edt(cells)) * cell_m).astype(np.float32)


def _coarsen(wall: np.ndarray, k: int) -> np.ndarray:
    ny, nx = wall.shape
    py, px = -ny % k, -nx % k
    w = np.pad(wall, ((0, py), (0, px)))
    return w.reshape(w.shape[0] // k, k, w.shape[1] // k, k).any(axis=(1, 3))


# --------------------------------------------------------------------------- FreeSpace


@dataclass(frozen=True, eq=False)
class FreeSpace:
    """A map's free space on a grid (rows are y, columns x; cell (i, j) is centred at
    ``origin + (j + 0.5, i + 0.5) * cell_m``)."""

    origin: tuple[float, float]
    """World (x, y) of the grid's lower-left corner."""
    config: FreeSpaceConfig
    """How it was computed."""
    wall: np.ndarray
    """(ny, nx) bool: cells a wall passes through."""
    dist: np.ndarray
    """(ny, nx) float32: grid distance in metres from each cell centre to the nearest wall cell."""
    region: np.ndarray
    """(ny, nx) int32: the inside region of each cell where the robot fits, 0 the largest; -1 elsewhere."""
    region_area_m2: np.ndarray
    """(R,) area of each region, largest first."""
    outside_area_m2: float
    """Free area (robot-sized) outside the building, within the padded extent."""
    n_voids: int
    """Inside free components smaller than ``min_region_area_m2``."""
    _cells: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def cell_m(self) -> float:
        """Grid cell size."""
        return self.config.cell_m

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx)."""
        return self.dist.shape  # type: ignore[return-value]

    @property
    def error_m(self) -> float:
        """Bound on |grid distance - exact distance to the walls|."""
        return self.config.error_m

    @property
    def n_regions(self) -> int:
        """Number of inside regions."""
        return int(self.region_area_m2.size)

    def clearance(self) -> np.ndarray:
        """(ny, nx) lower bound of each cell centre's exact distance to the walls."""
        return self.dist - np.float32(self.error_m)

    def cell_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of world points (..., 2), clipped to the grid."""
        p = np.asarray(xy, dtype=np.float64)
        c = self.cell_m
        j = np.clip(np.floor((p[..., 0] - self.origin[0]) / c).astype(np.int64), 0, self.shape[1] - 1)
        i = np.clip(np.floor((p[..., 1] - self.origin[1]) / c).astype(np.int64), 0, self.shape[0] - 1)
        return i, j

    def centres(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """World (..., 2) centres of cells."""
        c = self.cell_m
        return np.stack([self.origin[0] + (np.asarray(cols) + 0.5) * c, self.origin[1] + (np.asarray(rows) + 0.5) * c], axis=-1)

    def region_at(self, xy: np.ndarray) -> np.ndarray:
        """Region of the cell under each point (-1 where the robot does not fit or outside)."""
        i, j = self.cell_of(xy)
        return self.region[i, j]

    def free_cells(self, min_clearance_m: float, region: int | None = 0, cache: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) (int32) of cells at least ``min_clearance_m`` from every wall, in
        ``region`` (``None``: any region). Kept for the next call unless ``cache`` is
        false: placement draws many points at a few clearances, whereas a caller that
        asks once would hold a building's million cells for nothing."""
        key = (float(min_clearance_m), region)
        if key in self._cells:
            return self._cells[key]
        ok = self.clearance() >= min_clearance_m
        ok &= (self.region >= 0) if region is None else (self.region == region)
        rows, cols = np.nonzero(ok)
        cells = (rows.astype(np.int32), cols.astype(np.int32))
        if cache:
            self._cells[key] = cells
        return cells

    def sample_cells(self, min_clearance_m: float, region: int | None = 0) -> tuple[np.ndarray, np.ndarray]:
        """The cells :meth:`sample` draws from (kept): those whose whole area lies at
        least ``min_clearance_m`` from every wall. A long run that will draw places later
        calls this at its start, so that its memory does not step at the first draw."""
        return self.free_cells(min_clearance_m + math.sqrt(0.5) * self.cell_m, region)

    def sample(self, rng: np.random.Generator, n: int, min_clearance_m: float, region: int | None = 0) -> np.ndarray:
        """``n`` points (n, 2) uniform over the free space at least ``min_clearance_m`` from
        every wall (exactly: the jitter inside a cell is covered by the threshold)."""
        rows, cols = self.sample_cells(min_clearance_m, region)
        if rows.size == 0:
            where = "in any region" if region is None else f"in region {region}"
            raise InputError(f"free space: no place {where} at least {min_clearance_m:.2f} m from every wall")
        k = rng.integers(rows.size, size=n)
        jitter = rng.uniform(-0.5, 0.5, size=(n, 2)) * self.cell_m
        return self.centres(rows[k], cols[k]) + jitter


def build_free_space(vm: VectorMap, cfg: FreeSpaceConfig = FreeSpaceConfig()) -> FreeSpace:  # noqa: B008
    """Rasterise ``vm``, take its distance transform and find the inside regions where a
    robot of ``cfg.robot_radius_m`` fits. One-line :class:`InputError` when there are none."""
    name = vm.name or "the map"
    seg = np.ascontiguousarray(vm.segments, dtype=np.float64)
    xmin, ymin, xmax, ymax = vm.extent()
    c, pad = cfg.cell_m, cfg.padding_m
    x0, y0 = xmin - pad, ymin - pad
    nx = int(math.ceil((xmax - xmin + 2 * pad) / c))
    ny = int(math.ceil((ymax - ymin + 2 * pad) / c))
    if nx * ny > MAX_GRID_CELLS:
        raise InputError(
            f"{name}: a {xmax - xmin:.0f} x {ymax - ymin:.0f} m map needs {nx * ny:,} cells of {c} m "
            f"(limit {MAX_GRID_CELLS:,}); is it in millimetres, or give a larger free_space.cell_m"
        )
    wall = rasterise(seg, x0, y0, c, ny, nx)
    dist = grid_distance(wall, c)
    robot_ok = dist - np.float32(cfg.error_m) >= cfg.robot_radius_m
    lab, sizes = label_components(robot_ok)
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    border = border[border >= 0].astype(np.int64)
    inside = robot_ok.copy()
    outside_cells = 0
    if border.size:
        k = max(1, int(round(0.25 / c)))
        enclosed = _enclosed(lab, border, _coarsen(wall, k), k, cfg.enclosure_rays, cfg.enclosure_max_escapes)
        on_border = np.isin(lab, border)
        inside &= ~on_border | enclosed
        outside_cells = int(np.count_nonzero(on_border & ~enclosed))
    reg, rsizes = label_components(inside)
    area = rsizes * c * c
    keep = np.flatnonzero(area >= cfg.min_region_area_m2)
    order = keep[np.argsort(-area[keep], kind="stable")]
    remap = np.full(rsizes.size + 1, -1, dtype=np.int32)
    remap[order] = np.arange(order.size, dtype=np.int32)
    region = remap[reg]  # reg == -1 maps to remap[-1] == -1
    if order.size == 0:
        if outside_cells:
            raise InputError(
                f"{name}: no space inside the walls fits a robot of radius {cfg.robot_radius_m:.2f} m; "
                "only the outside of the building is free (the walls enclose no room for it)"
            )
        raise InputError(f"{name}: no free space fits a robot of radius {cfg.robot_radius_m:.2f} m")
    return FreeSpace(
        origin=(float(x0), float(y0)),
        config=cfg,
        wall=wall,
        dist=dist,
        region=region,
        region_area_m2=area[order].astype(np.float64),
        outside_area_m2=float(outside_cells * c * c),
        n_voids=int(rsizes.size - order.size),
    )
