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

Open maps (a parking lot, a campus of building faces): walls that close no inside. There
the free space is every cell within the convex hull of the walls' end points where the
robot fits. A map is taken as open when ``open_map`` says so, or (``open_map`` None) when
its walls are sparse (under ``open_wall_density`` metres of wall per square metre of the
hull; the real building floors we measured have 0.2 to 1.2, a parking lot and a campus
under 0.03) or the inside found is under ``open_fraction`` of the hull's area.

Large maps: when the extent needs more than ``max_cells`` cells of ``cell_m``, the grid
is made coarser (the smallest whole centimetre that fits, at most half the robot's
radius). Every clearance threshold subtracts the coarser grid's error bound, so the free
space only shrinks (narrow doors may close); it never admits a place nearer a wall than
the robot's radius.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numba
import numpy as np

from autonomy.common.constants import ROBOT_RADIUS_M
from autonomy.common.errors import InputError, require_int, require_positive
from autonomy.maps.vectormap import VectorMap

__all__ = [
    "FreeSpaceConfig", "FreeSpace", "build_free_space", "rasterise", "grid_distance", "label_components", "MAX_GRID_CELLS",
    "grid_cell_m", "convex_hull", "hull_mask", "polygon_area",
]

#: The largest grid :func:`build_free_space` makes by default (a 250 x 250 m floor at 5 cm
#: cells; larger maps get coarser cells).
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
    open_map: bool | None = None
    """True: the walls close no inside, all free space within their convex hull counts.
    False: only what the walls enclose. None: open when the enclosed free area is under
    ``open_fraction`` of the hull's area."""
    open_fraction: float = 0.05
    """Open-map detection: an enclosed free area under this share of the hull (real floors: 16 % or more)."""
    open_wall_density: float = 0.08
    """Open-map detection: fewer metres of wall per square metre of the hull than this."""
    max_cells: int = MAX_GRID_CELLS
    """Largest grid: a larger extent gets coarser cells (at most half the robot radius)."""

    def __post_init__(self) -> None:
        require_positive(self, "free_space.", "cell_m", "robot_radius_m", "padding_m", "min_region_area_m2", "open_fraction",
                         "open_wall_density")
        require_int(self, "free_space.", "enclosure_rays", minimum=4)
        require_int(self, "free_space.", "enclosure_max_escapes", minimum=0)
        require_int(self, "free_space.", "max_cells", minimum=10_000)
        if self.open_map not in (None, True, False):
            raise InputError(f"free_space.open_map: expected true, false or none, got {self.open_map!r}")
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
def _ray_escapes(coarse: np.ndarray, cy: float, cx: float, n_rays: int, stop: int) -> int:  # pragma: no cover - numba
    """How many of ``n_rays`` rays from (cy, cx) (coarse-cell units) leave the grid
    without meeting a wall cell (counting stops at ``stop``: in open space nearly every
    ray escapes, and each is long)."""
    ny, nx = coarse.shape
    esc = 0
    for r in range(n_rays):
        if esc >= stop:
            break
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
            if _ray_escapes(coarse, by / k + 0.5, bx / k + 0.5, n_rays, max_escapes + 1) > max_escapes:
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


@numba.njit(cache=True)
def _fill_rows(lo: np.ndarray, hi: np.ndarray, x0: float, cell: float, nx: int) -> np.ndarray:  # pragma: no cover - numba
    """(ny, nx) mask of the cells whose centre x lies in [lo[row], hi[row]]."""
    ny = lo.shape[0]
    out = np.zeros((ny, nx), dtype=np.bool_)
    for y in range(ny):
        if not lo[y] <= hi[y]:
            continue
        a = max(0, int(math.ceil((lo[y] - x0) / cell - 0.5)))
        b = min(nx - 1, int(math.floor((hi[y] - x0) / cell - 0.5)))
        for x in range(a, b + 1):
            out[y, x] = True
    return out


def convex_hull(points: np.ndarray) -> np.ndarray:
    """(H, 2) counter-clockwise convex hull of (N, 2) points (Andrew's monotone chain)."""
    p = np.unique(np.asarray(points, dtype=np.float64).reshape(-1, 2), axis=0)
    if len(p) < 3:
        return p

    def half(pts: np.ndarray) -> list:
        h: list = []
        for q in pts:
            while len(h) >= 2 and (h[-1][0] - h[-2][0]) * (q[1] - h[-2][1]) - (h[-1][1] - h[-2][1]) * (q[0] - h[-2][0]) <= 0:
                h.pop()
            h.append(q)
        return h

    lower, upper = half(p), half(p[::-1])
    return np.array(lower[:-1] + upper[:-1])


def polygon_area(poly: np.ndarray) -> float:
    """Area of a simple polygon (shoelace)."""
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def hull_mask(hull: np.ndarray, origin: tuple[float, float], cell: float, shape: tuple[int, int]) -> np.ndarray:
    """(ny, nx) cells whose centre lies in the convex polygon ``hull``."""
    ny, nx = shape
    yc = origin[1] + (np.arange(ny) + 0.5) * cell
    lo, hi = np.full(ny, np.inf), np.full(ny, -np.inf)
    if len(hull) >= 3:
        a, b = hull, np.roll(hull, -1, axis=0)
        for (ax, ay), (bx, by) in zip(a, b, strict=True):
            ylo, yhi = min(ay, by), max(ay, by)
            on = (yc >= ylo) & (yc <= yhi)
            if not on.any():
                continue
            if ay == by:
                x = np.array([min(ax, bx), max(ax, bx)])
                lo[on] = np.minimum(lo[on], x[0])
                hi[on] = np.maximum(hi[on], x[1])
            else:
                x = ax + (yc[on] - ay) * (bx - ax) / (by - ay)
                lo[on] = np.minimum(lo[on], x)
                hi[on] = np.maximum(hi[on], x)
    return _fill_rows(lo, hi, origin[0], cell, nx)


def grid_cell_m(extent: tuple[float, float, float, float], cfg: FreeSpaceConfig) -> tuple[float, float, int, int]:
    """(cell size, padding, nx, ny) of the grid for a map of ``extent``: ``cfg.cell_m``,
    or the smallest whole centimetre above it that keeps the grid within ``cfg.max_cells``.
    None of it fits (a map in millimetres, or larger than the coarsest grid allows): a
    one-line :class:`InputError`."""
    xmin, ymin, xmax, ymax = extent
    w, h = xmax - xmin, ymax - ymin

    def size(c: float) -> tuple[float, int, int]:
        pad = max(cfg.padding_m, cfg.robot_radius_m + 2 * c)
        return pad, int(math.ceil((w + 2 * pad) / c)), int(math.ceil((h + 2 * pad) / c))

    c = cfg.cell_m
    pad, nx, ny = size(c)
    if nx * ny <= cfg.max_cells:
        return c, pad, nx, ny
    coarsest = max(c, cfg.robot_radius_m / 2)
    c = max(c, math.ceil(100 * math.sqrt(nx * ny / cfg.max_cells) * cfg.cell_m - 1e-9) / 100)
    while c <= coarsest + 1e-12:
        pad, nx, ny = size(c)
        if nx * ny <= cfg.max_cells:
            return c, pad, nx, ny
        c = round(c + 0.01, 2)
    _, nx, ny = size(cfg.cell_m)
    raise InputError(
        f"a {w:.0f} x {h:.0f} m map needs {nx * ny:,} cells of {cfg.cell_m} m, more than {cfg.max_cells:,} "
        f"even at {coarsest:.3f} m cells (half the robot radius); is it in millimetres?"
    )


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
    is_open: bool = False
    """The map was taken as open: its regions are all free space within the walls' convex hull."""
    hull_area_m2: float = 0.0
    """Area of the convex hull of the walls' end points."""
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
    robot of ``cfg.robot_radius_m`` fits (on an open map: all free space within the walls'
    convex hull). The returned ``config`` holds the cell size used (coarser than
    ``cfg.cell_m`` on a large map). One-line :class:`InputError` when there is no region."""
    name = vm.name or "the map"
    seg = np.ascontiguousarray(vm.segments, dtype=np.float64)
    xmin, ymin, xmax, ymax = vm.extent()
    try:
        c, pad, nx, ny = grid_cell_m((xmin, ymin, xmax, ymax), cfg)
    except InputError as e:
        raise InputError(f"{name}: {e}") from None
    if c != cfg.cell_m or pad != cfg.padding_m:
        cfg = replace(cfg, cell_m=c, padding_m=pad)
    x0, y0 = xmin - pad, ymin - pad
    wall = rasterise(seg, x0, y0, c, ny, nx)
    dist = grid_distance(wall, c)
    robot_ok = dist - np.float32(cfg.error_m) >= cfg.robot_radius_m
    hull = convex_hull(seg.reshape(-1, 2))
    hull_area = polygon_area(hull)
    is_open = bool(cfg.open_map) or (cfg.open_map is None and vm.total_length_m < cfg.open_wall_density * hull_area)
    inside = None
    if not is_open:
        inside = _enclosed_free(robot_ok, wall, cfg)
        if cfg.open_map is None and hull_area > 0:
            is_open = np.count_nonzero(inside) * c * c < cfg.open_fraction * hull_area
    if is_open:
        inside = robot_ok & hull_mask(hull, (x0, y0), c, (ny, nx))
    assert inside is not None
    outside_cells = int(np.count_nonzero(robot_ok & ~inside))
    del robot_ok
    reg, rsizes = label_components(inside)
    del inside
    area = rsizes * c * c
    keep = np.flatnonzero(area >= cfg.min_region_area_m2)
    order = keep[np.argsort(-area[keep], kind="stable")]
    remap = np.full(rsizes.size + 1, -1, dtype=np.int32)
    remap[order] = np.arange(order.size, dtype=np.int32)
    region = remap[reg]  # reg == -1 maps to remap[-1] == -1
    if order.size == 0:
        if outside_cells and cfg.open_map is not True:
            raise InputError(
                f"{name}: no space inside the walls fits a robot of radius {cfg.robot_radius_m:.2f} m; "
                "only the outside of the building is free (the walls enclose no room for it; "
                "an open site such as a parking lot: --open)"
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
        is_open=is_open,
        hull_area_m2=hull_area,
    )


def _enclosed_free(robot_ok: np.ndarray, wall: np.ndarray, cfg: FreeSpaceConfig) -> np.ndarray:
    """The cells of ``robot_ok`` inside the building: not connected to the grid's border,
    or connected but enclosed by walls (the ray test of the module docstring)."""
    lab, _ = label_components(robot_ok)
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    border = border[border >= 0].astype(np.int64)
    inside = robot_ok.copy()
    if border.size:
        # rays from blocks of about 0.25 m, fewer on a large grid (the cost grows as the
        # cube of the number of blocks per side)
        k = max(1, int(round(0.25 / cfg.cell_m)), int(math.ceil(math.sqrt(robot_ok.size / 4e6))))
        enclosed = _enclosed(lab, border, _coarsen(wall, k), k, cfg.enclosure_rays, cfg.enclosure_max_escapes)
        inside &= ~np.isin(lab, border) | enclosed
    return inside
