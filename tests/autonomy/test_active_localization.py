"""Active localization's drive value against closed-form ranges and a corridor whose
two stretches look alike until one of them reaches a side door."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.localization.active_localization import (
    ActiveLocalizationConfig,
    drive_value,
    predicted_ranges,
    view_poses,
)
from autonomy.maps.raycast import scene_lines

FOV = math.radians(57.0)


def lines_of(segments: np.ndarray, max_range_m: float = 20.0):
    seg = np.asarray(segments, dtype=np.float64)
    return lambda x, y: scene_lines(seg, x, y, max_range_m=max_range_m)[0]


def box(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return [[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]]


def corridor(door: tuple[float, float] | None = (27.0, 29.0)) -> np.ndarray:
    """A corridor 40 m long and 2 m wide; its north wall has a door (a gap) at ``door``."""
    seg = [[0.0, 0.0, 40.0, 0.0], [0.0, 0.0, 0.0, 2.0], [40.0, 0.0, 40.0, 2.0]]
    if door is None:
        seg.append([0.0, 2.0, 40.0, 2.0])
    else:
        seg += [[0.0, 2.0, door[0], 2.0], [door[1], 2.0, 40.0, 2.0]]
    return np.array(seg)


def test_predicted_ranges_in_a_square_room_are_the_distances_to_its_walls() -> None:
    f = lines_of(np.array(box(-5.0, -5.0, 5.0, 5.0)))
    poses = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, math.pi / 2]])
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2])
    r = predicted_ranges(f, poses, angles, 5.5)
    np.testing.assert_allclose(r, [[4.0, 5.0, 5.5, 5.0], [3.0, 5.0, 7.0 - 1.5, 5.0]], atol=1e-9)


def test_predicted_ranges_with_nothing_in_view_are_the_cap() -> None:
    r = predicted_ranges(lambda x, y: np.zeros((0, 4)), np.zeros((2, 3)), np.zeros(3), 4.0)
    np.testing.assert_array_equal(r, np.full((2, 3), 4.0))


def test_view_poses_step_along_the_path_facing_along_it_and_stop_at_the_length() -> None:
    path = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 5.0]])
    v = view_poses(path, 6.5, 1.0)
    np.testing.assert_allclose(v[:, 0], [0, 1, 2, 3, 3, 3, 3, 3], atol=1e-12)
    np.testing.assert_allclose(v[:, 1], [0, 0, 0, 0, 1, 2, 3, 3.5], atol=1e-12)
    np.testing.assert_allclose(v[:3, 2], 0.0)
    np.testing.assert_allclose(v[3:, 2], math.pi / 2)  # at the corner, facing the way on
    assert len(view_poses(path[:1], 6.0, 1.0)) == 0


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20)), min_size=2, max_size=6),
    st.floats(0.1, 30.0),
    st.floats(0.2, 3.0),
)
def test_view_poses_lie_on_the_path_at_the_step(pts, length, step) -> None:
    path = np.array(pts)
    v = view_poses(path, length, step)
    total = float(np.hypot(*np.diff(path, axis=0).T).sum())
    if total < 1e-9:
        assert len(v) == 0
        return
    np.testing.assert_allclose(v[0, :2], path[0], atol=1e-9)
    # Consecutive viewpoints are at most a step apart (straight-line distance), and
    # there are as many as the cut length asks for.
    gaps = np.hypot(*np.diff(v[:, :2], axis=0).T)
    assert np.all(gaps <= step + 1e-9)
    assert len(v) == math.ceil(min(length, total) / step - 1e-9) + 1 or min(length, total) < 1e-6


def test_a_drive_towards_the_door_tells_two_alike_stretches_of_corridor_apart() -> None:
    """Two modes 6 m apart in a corridor see the same two parallel walls. Driving 6 m
    east takes the eastern one into view of the door, so the drive tells them apart;
    driving west keeps both in plain corridor (the west end is beyond the camera's 4 m)."""
    f = lines_of(corridor())
    cfg = ActiveLocalizationConfig()
    modes = np.array([[14.0, 1.0, 0.0], [20.0, 1.0, 0.0]])
    east = np.array([[14.0, 1.0], [26.0, 1.0]])
    west = np.array([[14.0, 1.0], [5.0, 1.0]])
    v_east = drive_value(f, east, modes, cfg, 6.0, FOV, 4.0)
    v_west = drive_value(f, west, modes, cfg, 6.0, FOV, 4.0)
    assert v_west == 0.0
    assert v_east > 0.3
    # Without the door no drive tells them apart.
    plain = lines_of(corridor(door=None))
    assert drive_value(plain, east, modes, cfg, 6.0, FOV, 4.0) == 0.0


def test_the_drive_is_carried_into_each_mode_as_motion_relative_to_it() -> None:
    """A mode facing the other way walks the same plan backwards on the map: planned
    east on the first mode, the drive takes a mode facing west (at x = 32) towards the
    west end, where it sees the door at 27-29 m; the first sees plain corridor."""
    f = lines_of(corridor())
    cfg = ActiveLocalizationConfig()
    east = np.array([[8.0, 1.0], [20.0, 1.0]])
    same = np.array([[8.0, 1.0, 0.0], [36.0, 1.0, math.pi]])  # no door within 4 m of 36-30
    assert drive_value(f, east, same, cfg, 6.0, FOV, 4.0) > 0.3
    far = np.array([[8.0, 1.0, 0.0], [12.0, 1.0, math.pi]])  # walks west to x = 6: plain
    assert drive_value(f, east, far, cfg, 6.0, FOV, 4.0) == 0.0


def test_pairs_are_counted_once_each_up_to_one() -> None:
    f = lines_of(corridor())
    cfg = ActiveLocalizationConfig()
    east = np.array([[14.0, 1.0], [26.0, 1.0]])
    three = np.array([[14.0, 1.0, 0.0], [20.0, 1.0, 0.0], [8.0, 1.0, 0.0]])
    # The eastern mode differs from both others as from one; the two western ones stay alike.
    one = drive_value(f, east, three[:2], cfg, 6.0, FOV, 4.0)
    assert one > 0.0
    assert drive_value(f, east, three, cfg, 6.0, FOV, 4.0) == pytest.approx(2.0 * one)
    # A pair counts at most once, however much of the view differs.
    wide = ActiveLocalizationConfig(told_apart=0.01)
    assert drive_value(f, east, three, wide, 6.0, FOV, 4.0) == pytest.approx(2.0)
    assert drive_value(f, east, three[:1], cfg, 6.0, FOV, 4.0) == 0.0


def test_config_rejects_bad_values() -> None:
    with pytest.raises(InputError, match="recovery.active.told_apart"):
        ActiveLocalizationConfig(told_apart=0.0)
    with pytest.raises(InputError, match="recovery.active.score_margin"):
        ActiveLocalizationConfig(score_margin=-1.0)
