"""PNG map renders: valid files, markers/trajectories, speed on a 9,000-segment map."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from autonomy.common.errors import InputError
from sim.simulator.blueprints import BuildingConfig, generate_building, small_floor
from sim.viz.maps import render_map

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and data[12:16] == b"IHDR"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_render_small_floor_with_everything(tmp_path):
    bp = small_floor()
    traj = np.column_stack([np.linspace(1, 14, 50), np.full(50, 5.1), np.zeros(50)])
    out = render_map(
        bp.vectormap,
        tmp_path / "deep" / "small.png",
        bp.navgraph,
        trajectories={"truth": traj, "estimate": traj[:, :2] + 0.1},
        markers={"resets": np.array([[3.0, 5.0], [8.0, 5.2]]), "goal": np.array([14.5, 8.5]), "none": np.zeros((0, 2))},
        title="small floor",
        dpi=100,
    )
    assert out == tmp_path / "deep" / "small.png"
    w, h = _png_size(out)
    assert w >= 600 and h >= 300
    assert out.stat().st_size > 10_000


def test_render_map_only_and_no_pyplot_state(tmp_path):
    had_pyplot = "matplotlib.pyplot" in sys.modules
    out = render_map(small_floor().vectormap, str(tmp_path / "walls.png"))
    assert _png_size(out)[0] > 0
    if not had_pyplot:
        assert "matplotlib.pyplot" not in sys.modules


def test_render_bad_trajectory(tmp_path):
    with pytest.raises(InputError, match="trajectory 'x'"):
        render_map(small_floor().vectormap, tmp_path / "bad.png", trajectories={"x": np.zeros((3, 1))})


def test_render_9000_segments(tmp_path):
    """The 100 x 100 m floor renders to a full-size PNG (``make bench``'s map_render_9000 times it)."""
    bp = generate_building(BuildingConfig.large(), 0)
    assert bp.vectormap.n_segments >= 9000
    out = render_map(bp.vectormap, tmp_path / "large.png", bp.navgraph, dpi=120)
    assert out.stat().st_size > 50_000


def _grey_pixels(png) -> int:
    from matplotlib.image import imread

    img = (imread(str(png))[..., :3] * 255).round()
    return int((np.abs(img - 189).max(axis=2) <= 2).sum())  # the furniture's face colour, #bdbdbd


def test_furniture_is_drawn_where_it_stands_and_routes_are_drawn(tmp_path):
    from tests.helpers import box_room

    vm = box_room(10.0, 6.0)
    empty = render_map(vm, tmp_path / "a.png", dpi=60)
    one = render_map(vm, tmp_path / "b.png", dpi=60, boxes=np.array([[5.0, 3.0, 0.3, 2.0, 1.0]]))
    two = render_map(vm, tmp_path / "c.png", dpi=60, boxes=np.array([[5.0, 3.0, 0.3, 2.0, 1.0], [2.0, 2.0, 0.0, 2.0, 1.0]]),
                     routes=[np.array([[1.0, 1.0], [9.0, 5.0]])])
    g0, g1, g2 = _grey_pixels(empty), _grey_pixels(one), _grey_pixels(two)
    # A 2 m2 box at 60 dpi on a 10 m wide map covers some hundreds of pixels; two boxes twice that.
    assert g0 < 50 and g1 > 200 and 1.6 < (g2 - g0) / (g1 - g0) < 2.4, (g0, g1, g2)
