"""Numpy rasterising for the gymnasium env's ``render()``: a top-down map and a depth view.

No matplotlib per frame: the walls and the navigation graph are drawn once per building
into a background image; each frame copies it and draws furniture, people, the path,
the goal, the camera's view, the particles and the robot with a few array operations
(:func:`top_view`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from autonomy.maps.navgraph import NavGraph
from autonomy.maps.vectormap import VectorMap

if TYPE_CHECKING:
    from sim.envs.config import EnvConfig
    from sim.envs.loop import Reading
    from sim.envs.site import Site
    from sim.envs.task import Episode

BACKGROUND = (250, 250, 247)
WALL = (40, 40, 45)
GRAPH = (200, 215, 235)
FURNITURE = (150, 110, 70)
PERSON = (230, 120, 60)
PATH = (40, 170, 80)
GOAL = (215, 40, 40)
ROBOT = (40, 80, 200)
ESTIMATE = (190, 50, 190)
PARTICLE = (190, 50, 190)
FRUSTUM = (170, 190, 230)


def draw_segments(img: np.ndarray, p0: np.ndarray, p1: np.ndarray, color, thickness: int = 1) -> None:
    """Draw line segments between pixel coordinates p0[i] and p1[i] ((n, 2) as u, v)."""
    p0 = np.asarray(p0, dtype=np.float64).reshape(-1, 2)
    p1 = np.asarray(p1, dtype=np.float64).reshape(-1, 2)
    if not len(p0):
        return
    d = p1 - p0
    steps = np.ceil(np.abs(d).max(axis=1)).astype(np.int64) + 1
    steps = np.minimum(steps, 20000)
    seg = np.repeat(np.arange(len(p0)), steps)
    start = np.repeat(np.cumsum(steps) - steps, steps)
    t = (np.arange(len(seg)) - start) / np.maximum(np.repeat(steps - 1, steps), 1)
    pts = p0[seg] + t[:, None] * d[seg]
    draw_points(img, pts, color, size=thickness)


def draw_points(img: np.ndarray, pts: np.ndarray, color, size: int = 1) -> None:
    """Set the pixels at (n, 2) u, v coordinates (``size`` x ``size`` squares)."""
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    if not len(pts):
        return
    h, w = img.shape[:2]
    u0 = np.rint(pts[:, 0]).astype(np.int64)
    v0 = np.rint(pts[:, 1]).astype(np.int64)
    lo = -(size // 2)
    for du in range(lo, lo + size):
        for dv in range(lo, lo + size):
            u, v = u0 + du, v0 + dv
            ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
            img[v[ok], u[ok]] = color


def draw_disk(img: np.ndarray, cu: float, cv: float, r: float, color, ring: bool = False) -> None:
    """A filled disk (or a one-pixel ring) of radius r pixels centred at (cu, cv)."""
    h, w = img.shape[:2]
    u0, u1 = max(int(math.floor(cu - r - 1)), 0), min(int(math.ceil(cu + r + 1)), w - 1)
    v0, v1 = max(int(math.floor(cv - r - 1)), 0), min(int(math.ceil(cv + r + 1)), h - 1)
    if u0 > u1 or v0 > v1:
        return
    vv, uu = np.mgrid[v0 : v1 + 1, u0 : u1 + 1]
    d2 = (uu - cu) ** 2 + (vv - cv) ** 2
    mask = d2 <= r * r
    if ring:
        mask &= d2 >= max(r - 1.2, 0.0) ** 2
    img[v0 : v1 + 1, u0 : u1 + 1][mask] = color


def fill_convex(img: np.ndarray, poly: np.ndarray, color) -> None:
    """Fill a convex polygon given as (k, 2) pixel coordinates in either winding."""
    poly = np.asarray(poly, dtype=np.float64)
    h, w = img.shape[:2]
    u0, u1 = max(int(math.floor(poly[:, 0].min())), 0), min(int(math.ceil(poly[:, 0].max())), w - 1)
    v0, v1 = max(int(math.floor(poly[:, 1].min())), 0), min(int(math.ceil(poly[:, 1].max())), h - 1)
    if u0 > u1 or v0 > v1:
        return
    vv, uu = np.mgrid[v0 : v1 + 1, u0 : u1 + 1]
    a, b = poly, np.roll(poly, -1, axis=0)
    cross = (b[:, 0, None, None] - a[:, 0, None, None]) * (vv - a[:, 1, None, None]) - (
        b[:, 1, None, None] - a[:, 1, None, None]
    ) * (uu - a[:, 0, None, None])
    mask = np.all(cross >= -0.5, axis=0) | np.all(cross <= 0.5, axis=0)
    img[v0 : v1 + 1, u0 : u1 + 1][mask] = color


class MapCanvas:
    """A fixed-size top-down view of one building (map fitted and centred, y up)."""

    def __init__(self, vm: VectorMap, graph: NavGraph | None, size: tuple[int, int], margin_px: int = 8) -> None:
        self.h, self.w = int(size[0]), int(size[1])
        segs = np.asarray(vm.segments, dtype=np.float64).reshape(-1, 4)
        pts = [segs[:, :2], segs[:, 2:]]
        if graph is not None and graph.n_nodes:
            pts.append(graph.node_xy())
        allp = np.vstack(pts) if sum(len(p) for p in pts) else np.zeros((1, 2))
        x0, y0 = allp.min(axis=0)
        x1, y1 = allp.max(axis=0)
        span_x, span_y = max(x1 - x0, 1e-3), max(y1 - y0, 1e-3)
        self.scale = min((self.w - 2 * margin_px) / span_x, (self.h - 2 * margin_px) / span_y)
        self.ox = (self.w - span_x * self.scale) / 2 - x0 * self.scale
        self.oy = (self.h - span_y * self.scale) / 2 - y0 * self.scale
        bg = np.empty((self.h, self.w, 3), dtype=np.uint8)
        bg[:] = BACKGROUND
        if graph is not None and graph.n_edges:
            e = graph.edge_segments()
            draw_segments(bg, self.px(e[:, :2]), self.px(e[:, 2:]), GRAPH)
        if len(segs):
            draw_segments(bg, self.px(segs[:, :2]), self.px(segs[:, 2:]), WALL, thickness=2 if self.scale >= 12 else 1)
        self.background = bg

    def px(self, xy: np.ndarray) -> np.ndarray:
        """World (n, 2) x, y -> pixel (n, 2) u, v (v down)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out = np.empty_like(xy)
        out[:, 0] = xy[:, 0] * self.scale + self.ox
        out[:, 1] = self.h - 1 - (xy[:, 1] * self.scale + self.oy)
        return out


def top_view(site: Site, cfg: EnvConfig, fov_h_rad: float, depth_max_m: float, episode: Episode, reading: Reading) -> np.ndarray:
    """The ``rgb_array`` frame: the building with its furniture and people, the route to the
    goal, the goal, the camera's field of view, the CGR particles and estimate, and the robot."""
    if site.canvas is None:
        site.canvas = MapCanvas(site.building.vectormap, site.building.navgraph, cfg.render_size)
    cv = site.canvas
    assert isinstance(cv, MapCanvas)
    img = cv.background.copy()
    s = cv.scale
    pose = reading.pose
    # The camera's horizontal field of view out to the maximum range.
    cam = cfg.kinect.mount.translation()
    c, sn = math.cos(pose[2]), math.sin(pose[2])
    cxy = pose[:2] + np.array([c * cam[0] - sn * cam[1], sn * cam[0] + c * cam[1]])
    half = fov_h_rad / 2
    r = min(depth_max_m, 6.0)
    ends = np.array([cxy + r * np.array([math.cos(pose[2] + a), math.sin(pose[2] + a)]) for a in (-half, half)])
    draw_segments(img, cv.px(np.vstack([cxy, cxy])), cv.px(ends), FRUSTUM)
    for f in site.furniture:
        lx, ly, _ = f.dims
        cf, sf = math.cos(f.yaw), math.sin(f.yaw)
        corners = np.array([[sx * lx / 2, sy * ly / 2] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        world_c = np.column_stack([f.x + cf * corners[:, 0] - sf * corners[:, 1], f.y + sf * corners[:, 0] + cf * corners[:, 1]])
        fill_convex(img, cv.px(world_c), FURNITURE)
    people = site.world.people.positions()
    for i, p in enumerate(site.people):
        u, v = cv.px(people[i, :2])[0]
        draw_disk(img, u, v, max(2.0, p.radius_m * s), PERSON)
    path = episode.field.path(pose[:2])
    draw_segments(img, cv.px(path[:-1]), cv.px(path[1:]), PATH, thickness=2)
    gu, gv = cv.px(episode.goal)[0]
    draw_disk(img, gu, gv, max(3.0, 0.15 * s), GOAL)
    draw_disk(img, gu, gv, max(4.0, cfg.goal_radius_m * s), GOAL, ring=True)
    out = reading.output
    if out is not None and out.particles is not None:
        draw_points(img, cv.px(out.particles[:, :2]), PARTICLE)
    e = reading.estimate
    eu, ev = cv.px(e[:2])[0]
    draw_disk(img, eu, ev, max(2.0, 0.1 * s), ESTIMATE)
    ru, rv = cv.px(pose[:2])[0]
    rr = max(3.0, cfg.robot.radius_m * s)
    draw_disk(img, ru, rv, rr, ROBOT, ring=True)
    head = cv.px(pose[:2] + cfg.robot.radius_m * 1.6 * np.array([c, sn]))
    draw_segments(img, np.array([[ru, rv]]), head, ROBOT, thickness=2)
    return img


def turbo_lut() -> np.ndarray:
    """256 x 3 uint8 colour table of Google's Turbo map (polynomial fit, Mikhailov 2019)."""
    x = np.linspace(0.0, 1.0, 256)
    r = 0.13572138 + x * (4.61539260 + x * (-42.66032258 + x * (132.13108234 + x * (-152.94239396 + x * 59.28637943))))
    g = 0.09140261 + x * (2.19418839 + x * (4.84296658 + x * (-14.18503333 + x * (4.27729857 + x * 2.82956604))))
    b = 0.10667330 + x * (12.64194608 + x * (-60.58204836 + x * (110.36276771 + x * (-89.90310912 + x * 27.34824973))))
    return (np.clip(np.stack([r, g, b], axis=1), 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


_TURBO = turbo_lut()


def depth_to_rgb(depth: np.ndarray, max_depth_m: float, upscale: int = 1) -> np.ndarray:
    """Depth (m, 0 = invalid) as a Turbo-coloured uint8 RGB image; invalid pixels black."""
    q = np.clip(depth * (255.0 / max_depth_m), 0, 255).astype(np.uint8)
    rgb = _TURBO[q]
    rgb[depth <= 0] = 0
    if upscale > 1:
        rgb = np.repeat(np.repeat(rgb, upscale, axis=0), upscale, axis=1)
    return np.ascontiguousarray(rgb)
