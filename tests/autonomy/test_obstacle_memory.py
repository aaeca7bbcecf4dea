"""The obstacle memory kernel against a plain numpy reading of its definition (the
navigator's implementation before the kernel), over random frame sequences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.navigation.config import NavigatorConfig
from autonomy.navigation.navigator import Navigator
from autonomy.navigation.surroundings import WALL_STEP_M, in_camera_view, wall_points
from autonomy.perception.camera import DepthCamera


def _graph() -> NavGraph:
    nodes = tuple(NavNode(id=i, x=float(i), y=0.0) for i in range(3))
    edges = tuple(NavEdge(s0_id=i, s1_id=i + 1) for i in range(2))
    return NavGraph(nodes=nodes, edges=edges)


class ReferenceMemory:
    """Step 1-3 of autonomy/navigation/obstacle_memory.py with numpy set operations."""

    def __init__(self, cfg: NavigatorConfig, radius_m: float, walls: np.ndarray | None = None) -> None:
        self.cfg, self.radius_m, self.camera = cfg, radius_m, DepthCamera()
        self.mem, self.mem_t = np.zeros((0, 2)), np.zeros(0)
        self.wall_pts = np.zeros((0, 2)) if walls is None else wall_points(walls, WALL_STEP_M)

    def _wall_cells(self) -> set[tuple[int, int]]:
        """The cells where shadows end: those within reach of a wall point's cell."""
        cell = self.cfg.memory_cell_m
        reach = max(1, math.ceil(WALL_STEP_M / cell - 1e-9))
        cells = set()
        for x, y in self.wall_pts:
            i, j = round(x / cell), round(y / cell)
            cells.update((i + a, j + b) for a in range(-reach, reach + 1) for b in range(-reach, reach + 1))
        return cells

    def _blind(self, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        cam = self.camera
        return (bx > -cam.forward_m) & (np.hypot(bx, by) <= cam.min_range_m + 0.1) & (np.abs(by) < self.radius_m + 0.2)

    def remember(self, pose: np.ndarray, obs: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.cfg
        c, s = math.cos(pose[2]), math.sin(pose[2])
        xy = pose[:2]
        if len(self.mem):
            rel = self.mem - xy
            bx = c * rel[:, 0] + s * rel[:, 1] - self.camera.forward_m
            by = -s * rel[:, 0] + c * rel[:, 1]
            in_view = in_camera_view(bx, by, self.camera, fov_fraction=0.9, near_pad_m=0.1, far_pad_m=0.2)
            near = np.hypot(rel[:, 0], rel[:, 1]) <= cfg.memory_radius_m + 0.5
            age = t - self.mem_t
            young = age <= max(cfg.memory_s, cfg.backoff_memory_s, cfg.memory_beside_s)
            keep = (young | ((age <= cfg.memory_blind_s) & self._blind(bx, by))) & ~in_view & near
            self.mem, self.mem_t = self.mem[keep], self.mem_t[keep]
        new = obs[np.hypot(obs[:, 0], obs[:, 1]) <= cfg.memory_radius_m]
        # Each point's shadow: every cell behind it along the camera's sight line, up to
        # shadow_m beyond it, within the memory's keeping radius and short of the walls.
        ray = new - np.array([self.camera.forward_m, 0.0])
        unit = ray / np.maximum(np.hypot(ray[:, 0], ray[:, 1]), 1e-300)[:, None]
        walls = self._wall_cells()
        shadows = []
        for p, u in zip(new, unit, strict=True):
            for j in range(1, int(math.floor(cfg.shadow_m / cfg.memory_cell_m + 1e-9)) + 1):
                q = p + j * cfg.memory_cell_m * u
                w = (c * q[0] - s * q[1] + pose[0], s * q[0] + c * q[1] + pose[1])
                if not np.hypot(q[0], q[1]) <= cfg.memory_radius_m + 0.5 or (round(w[0] / cfg.memory_cell_m), round(w[1] / cfg.memory_cell_m)) in walls:
                    break
                shadows.append(q)
        new = np.vstack([new, np.reshape(shadows, (-1, 2))])
        # A dict of cells: old ones first, then this frame's overwrite with the time now.
        cells: dict[tuple[int, int], float] = {}
        for (x, y), tt in zip(self.mem, self.mem_t, strict=True):
            cells[(round(x / cfg.memory_cell_m), round(y / cfg.memory_cell_m))] = tt
        for x, y in new:
            w = (c * x - s * y + pose[0], s * x + c * y + pose[1])
            cells[(round(w[0] / cfg.memory_cell_m), round(w[1] / cfg.memory_cell_m))] = t
        keys = sorted(cells)
        self.mem = np.array([[i * cfg.memory_cell_m, j * cfg.memory_cell_m] for i, j in keys]).reshape(-1, 2)
        self.mem_t = np.array([cells[k] for k in keys])
        rel = self.mem - xy
        out = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]]).reshape(-1, 2)
        age = t - self.mem_t
        beside = (age <= cfg.memory_beside_s) & (np.hypot(out[:, 0], out[:, 1]) <= cfg.memory_beside_m)
        blind = (age <= cfg.memory_blind_s) & self._blind(out[:, 0] - self.camera.forward_m, out[:, 1])
        recent = (age <= cfg.memory_s) | beside | blind
        return out, out[recent]


WALLS = np.array([[-1.0, 1.2, 3.0, 1.2], [1.5, -2.0, 1.5, 0.4], [-0.3, -1.0, 0.8, -0.2]])
"""Map walls round the robot's frames, for the shadows to end at."""

frame = st.tuples(
    st.floats(-0.4, 0.4),  # dx
    st.floats(-0.4, 0.4),  # dy
    st.floats(-1.0, 1.0),  # dyaw
    st.floats(0.02, 3.0),  # dt
    st.integers(0, 60),  # obstacle points
    st.integers(0, 2**31),  # their seed
)


@settings(max_examples=80, deadline=None)
@given(
    st.lists(frame, min_size=1, max_size=12),
    st.sampled_from([0.5, 2.0]),
    st.sampled_from([0.0, 30.0]),
    st.sampled_from([0.05, 0.03, 0.2]),
    st.sampled_from([0.0, 0.6, 0.33]),
    st.sampled_from([0.0, 10.0]),
    st.sampled_from([10.0, 2.5, 1000.0]),
    st.sampled_from([None, WALLS]),
)
# Wall points where a cell boundary falls (1.5 m on a 0.2 m grid): they must land on the
# same cell as in the reference, whatever the robot's position.
@example([(0.0, 0.0, 0.0, 1.0, 0, 0)] * 4 + [(0.25, 0.0, 0.0, 1.0, 0, 0), (0.0, 0.0, 0.0, 1.0, 33, 422)], 0.5, 0.0, 0.2, 0.6, 0.0, 10.0, WALLS)
def test_memory_kernel_matches_the_reference(
    frames, memory_s: float, backoff_s: float, cell: float, shadow_m: float, beside_s: float, blind_s: float, walls
) -> None:
    cfg = NavigatorConfig(
        memory_s=memory_s, backoff_memory_s=backoff_s, memory_cell_m=cell, shadow_m=shadow_m, memory_beside_s=beside_s, memory_blind_s=blind_s
    )
    nav = Navigator(_graph(), cfg, walls=walls)
    ref = ReferenceMemory(cfg, nav.avoid.radius_m, walls)
    pose, t = np.array([0.3, -0.2, 0.4]), 0.0
    for dx, dy, dyaw, dt, n, seed in frames:
        pose = pose + np.array([dx, dy, dyaw])
        t += dt
        rng = np.random.default_rng(seed)
        # Points all round the robot, some beyond the memory's radius, some on shared cells.
        obs = np.column_stack([rng.uniform(-2.6, 2.6, n), rng.uniform(-2.6, 2.6, n)])
        obs[: n // 3] = np.round(obs[: n // 3] / 0.1) * 0.1
        got = nav.surroundings.remember(pose, obs, t)
        want_all, want = ref.remember(pose, obs, t)
        np.testing.assert_allclose(nav.surroundings._mem, ref.mem, atol=1e-12)
        np.testing.assert_array_equal(nav.surroundings._mem_t, ref.mem_t)
        np.testing.assert_allclose(nav.surroundings.remembered, want_all, atol=1e-12)
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_memory_off_returns_the_frame() -> None:
    nav = Navigator(_graph(), NavigatorConfig(memory_s=0.0))
    obs = np.array([[1.0, 0.5], [0.0, 3.0]])
    np.testing.assert_array_equal(nav.surroundings.remember(np.zeros(3), obs, 0.0), obs)
    assert nav.surroundings.remembered.shape == (0, 2)


def test_non_finite_points_are_not_remembered() -> None:
    """A NaN or infinite point fails the sensing radius, as in the numpy code (a NaN
    cast to a grid cell would be an arbitrary cell)."""
    nav = Navigator(_graph(), NavigatorConfig(memory_s=2.0, shadow_m=0.0))
    obs = np.array([[np.nan, 0.5], [0.0, np.inf], [-0.5, 0.6]])
    got = nav.surroundings.remember(np.zeros(3), obs, 0.0)
    np.testing.assert_allclose(got, [[-0.5, 0.6]], atol=0.03)
    assert len(nav.surroundings._mem) == 1 and np.isfinite(nav.surroundings._mem).all()


def test_memory_grid_settings_are_checked() -> None:
    for bad in (0.0, -0.05, float("nan")):
        with pytest.raises(InputError, match=r"^navigator\.memory_cell_m: expected a positive number"):
            NavigatorConfig(memory_cell_m=bad)
    with pytest.raises(InputError, match=r"^navigator\.memory_radius_m: expected a positive number"):
        NavigatorConfig(memory_radius_m=0.0)
    # Too fine a grid for the radius (the kernel's dense local grid would be huge).
    with pytest.raises(InputError, match=r"^navigator\.memory_cell_m: expected at least .* = 0\.01 m, got 0\.001$"):
        NavigatorConfig(memory_cell_m=0.001)
    NavigatorConfig(memory_cell_m=0.01)


@pytest.mark.parametrize("field", ["shadow_m", "memory_beside_s", "memory_beside_m", "memory_blind_s"])
def test_shadow_and_beside_settings_are_checked(field: str) -> None:
    for bad in (-0.1, float("nan")):
        with pytest.raises(InputError, match=rf"^navigator\.{field}: expected a number >= 0"):
            NavigatorConfig(**{field: bad})
