"""The robot stack's frame guard on the shipped corridor_loop map, without a simulator:
dropped, NaN, invalid and stale frames (the map, the stack and the frames:
:mod:`tests.autonomy.stack_rig`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autonomy.common.geometry import compose_pose
from tests.autonomy.stack_rig import (
    FPS,
    SHAPE,
    START,
    corridor_loop,
    count_updates,
    make_stack,
    render,
    wall,
)


@pytest.fixture(scope="module")
def building():
    return corridor_loop()


# --------------------------------------------------------------------------- frame faults


def test_a_dropped_frame_keeps_the_last_perception_and_does_not_reach_cgr(building, monkeypatch) -> None:
    stack = make_stack(building)
    updates = count_updates(stack, monkeypatch)
    first = stack.perceive(wall())
    stack.localize(np.zeros(3), 0.0)
    assert stack.guard.fault == "" and updates[0] == 1 and len(first.points_2d) > 50
    again = stack.perceive(None)
    stack.localize(np.zeros(3), 1 / FPS)
    assert again is first and stack.guard.fault == "dropped" and updates[0] == 1
    assert stack.guard.rejected == {"dropped": 1, "stale": 0, "invalid": 0, "corrupt": 0} and stack.frame == 2
    # Dropped before any frame: an empty perception, not None.
    fresh = make_stack(building)
    empty = fresh.perceive(None)
    assert empty.points_2d.shape == (0, 2) and empty.obstacles.shape == (0, 2) and fresh.guard.fault == "dropped"


def test_nan_and_infinite_pixels_are_invalid_pixels(building) -> None:
    rng = np.random.default_rng(0)
    clean = render(building[1], START)
    bad = clean.copy()
    holes = rng.random(SHAPE) < 0.2
    bad[holes] = rng.choice(np.array([np.nan, np.inf, -np.inf], np.float32), holes.sum())
    as_zero = np.where(holes, np.float32(0.0), clean)
    a, b = make_stack(building), make_stack(building)
    pa = a.perceive(bad, seed=11)
    pb = b.perceive(as_zero, seed=11)
    assert a.guard.fault == "corrupt" and a.guard.rejected["corrupt"] == 1
    assert np.isnan(bad).any()  # the caller's frame is left as it was
    for arr in (pa.planes.points, pa.planes.normals, pa.planes.outliers, pa.points_2d, pa.normals_2d, pa.obstacles, pa.near_lines):
        assert np.isfinite(arr).all()
    # Exactly as if those pixels had been 0 (the Kinect's invalid value).
    assert len(pa.points_2d) > 50
    np.testing.assert_array_equal(pa.planes.points, pb.planes.points)
    np.testing.assert_array_equal(pa.points_2d, pb.points_2d)


@pytest.mark.parametrize("frame", ["zeros", "nan", "negative"])
def test_a_frame_without_a_valid_pixel_is_used_as_blocked_ahead(building, frame) -> None:
    stack = make_stack(building)
    stack.perceive(wall())
    depth = {"zeros": np.zeros(SHAPE, np.float32), "nan": np.full(SHAPE, np.nan, np.float32), "negative": wall(-1.0)}[frame]
    per = stack.perceive(depth)
    corrupt = int(frame == "nan")
    assert stack.guard.fault == "invalid" and stack.guard.rejected == {"dropped": 0, "stale": 0, "invalid": 1, "corrupt": corrupt}
    assert all(np.isfinite(a).all() for a in (per.points_2d, per.obstacles, per.near_lines))
    # Used, not refused: nothing to localize on, and the near field reads the blank view
    # as blocked right ahead (a failed camera and a door at 0.5 m look alike).
    assert len(per.points_2d) == 0 and len(per.near_lines) > 0
    # The next good frame is used again (and is not taken for a repeat of the last).
    stack.perceive(wall())
    stack.localize(np.array([0.05, 0.0, 0.0]), 0.1)
    assert stack.guard.fault == ""


def test_the_same_pixels_are_stale_once_the_wheels_turned_since_they_came(building, monkeypatch) -> None:
    stack = make_stack(building)
    updates = count_updates(stack, monkeypatch)
    depth = wall()
    stack.perceive(depth)
    stack.localize(np.zeros(3), 0.0)
    # Standing still, a still scene repeats itself: used.
    stack.perceive(depth.copy())
    stack.localize(np.zeros(3), 1 / FPS)
    assert stack.guard.fault == "" and updates[0] == 2
    # Moving (1 cm or 1 degree a frame), the same pixels again: a stuck driver.
    for k, inc in enumerate((np.array([0.01, 0.0, 0.0]), np.array([0.0, 0.0, math.radians(1.0)]))):
        stack.perceive(depth.copy())
        stack.localize(inc, (2 + k) / FPS)
        assert stack.guard.fault == "stale" and stack.guard.rejected["stale"] == k + 1 and updates[0] == 2
    # Stopped now, the stuck driver's pixels are still those of where the robot stood
    # before it moved: stale, though this frame's wheels did not turn.
    stack.perceive(depth)
    stack.localize(np.zeros(3), 4 / FPS)
    assert stack.guard.fault == "stale" and stack.guard.rejected["stale"] == 3 and updates[0] == 2
    # One sampled pixel different: a new frame.
    other = depth.copy()
    other.ravel()[7 * 1000] += 0.01
    stack.perceive(other)
    stack.localize(np.array([0.02, 0.0, 0.0]), 5 / FPS)
    assert stack.guard.fault == "" and updates[0] == 3
    # Repeated while the robot creeps less than the threshold in all since it came: used;
    # once the creep adds up past it: stale.
    for k in range(2):
        stack.perceive(other.copy())
        stack.localize(np.array([0.4e-3, 0.0, 0.4e-3]), (6 + k) / FPS)
        assert stack.guard.fault == "" and updates[0] == 4 + k
    stack.perceive(other.copy())
    stack.localize(np.array([0.4e-3, 0.0, 0.4e-3]), 8 / FPS)
    assert stack.guard.fault == "stale" and stack.guard.rejected["stale"] == 4 and updates[0] == 5
    # The odometry is dead-reckoned through stale frames too.
    want = START
    for inc in ([0.01, 0.0, 0.0], [0.0, 0.0, math.radians(1.0)], [0.0, 0.0, 0.0], [0.02, 0.0, 0.0]) + ([0.4e-3, 0.0, 0.4e-3],) * 3:
        want = compose_pose(want, np.array(inc))
    np.testing.assert_allclose(stack.state.odom, want, atol=1e-12)
