"""The safety layer under a velocity command: its braking speed in closed form, the stop
it promises checked against the exact first contact of a disc with each point, and its
choice checked against a brute-force search for the nearest safe velocity."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.navigation.avoidance import AvoidanceConfig
from autonomy.navigation.safety import (
    FAN_DIRECTIONS,
    SWEEP_SAMPLES,
    braking_speed,
    safe_command,
)

CFG = AvoidanceConfig(robot_radius_m=0.25, safety_margin_m=0.05, max_decel_mps2=1.0, stop_distance_m=0.05, max_range_m=4.0)
R = CFG.robot_radius_m + CFG.safety_margin_m


def exact_contact_m(points: np.ndarray, angle: float, radius: float) -> float:
    """How far a disc of ``radius`` moves along ``angle`` before it touches a point (brute force)."""
    c, s = math.cos(angle), math.sin(angle)
    best = math.inf
    for x, y in points:
        along, lateral = x * c + y * s, -x * s + y * c
        if along > 0 and abs(lateral) < radius:
            best = min(best, along - math.sqrt(radius * radius - lateral * lateral))
    return max(best, 0.0)


def stops_in_time(v: float, heading: float, omega: float, hold: float, points: np.ndarray) -> bool:
    """Travelling ``v`` for ``hold`` then braking stays short of the exact first contact
    along every direction the turning command sweeps (and of the range)."""
    sweep = np.linspace(heading, heading + omega * hold, SWEEP_SAMPLES)
    reach = min(exact_contact_m(points, a, R) for a in sweep)
    return v * hold + v * v / (2 * CFG.max_decel_mps2) <= min(reach, CFG.max_range_m) - CFG.stop_distance_m + 1e-9


def test_braking_speed_travels_then_stops_in_exactly_the_room() -> None:
    for room, hold in [(1.0, 0.2), (0.3, 0.2), (2.5, 0.0), (0.05, 1.0)]:
        v = braking_speed(room + 0.05, hold, 2.0, 0.05)
        assert v * hold + v * v / 4.0 == pytest.approx(room, rel=1e-12)
    assert braking_speed(0.04, 0.2, 1.0, 0.05) == 0.0
    np.testing.assert_allclose(braking_speed(np.array([0.04, 1.05]), 0.2, 2.0, 0.05), [0.0, braking_speed(1.05, 0.2, 2.0, 0.05)])


def test_a_safe_command_passes_and_one_straight_at_a_wall_slows_down() -> None:
    cmd = np.array([0.75, 0.0, 0.0])
    assert np.array_equal(safe_command(cmd, np.zeros((0, 2)), 0.2, CFG), cmd)
    wall = np.column_stack([np.full(81, 0.6), np.linspace(-4, 4, 81)])
    slowed = safe_command(cmd, wall, 0.2, CFG)
    assert 0 < slowed[0] < 0.75 and abs(slowed[1]) < 1e-12
    # Moving away from the wall or along it, or turning in place, passes.
    for free in ([-0.75, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 1.2]):
        assert np.array_equal(safe_command(np.array(free), wall, 0.2, CFG), free)
    # Touching it: no approach at all, only what runs along it.
    touching = safe_command(np.array([0.5, 0.3, 0.0]), wall - [0.3, 0.0], 0.2, CFG)
    assert touching[0] <= 1e-9 and touching[1] == pytest.approx(0.3, abs=0.02)


def test_a_command_at_a_wall_at_an_angle_slides_along_it() -> None:
    """Diagonally at a wall just ahead: the forward part is taken away, the sideways part kept."""
    wall = np.column_stack([np.full(81, 0.35), np.linspace(-4, 4, 81)])
    out = safe_command(np.array([0.75, 0.75, 0.0]), wall, 0.2, CFG)
    assert out[0] < 0.05 and out[1] > 0.5


def test_a_turning_command_is_slowed_for_what_its_sweep_reaches() -> None:
    """A post ahead-left is outside the straight corridor but inside the one the command
    turns into while it is held."""
    post = np.array([[0.6, 0.45]])
    cmd = np.array([0.75, 0.0, 0.0])
    assert np.array_equal(safe_command(cmd, post, 0.5, CFG), cmd)
    turning = np.array([0.75, 0.0, 1.5])
    assert math.hypot(*safe_command(turning, post, 0.5, CFG)[:2]) < 0.75


def eq4_open_m(points: np.ndarray, angle: float) -> float:
    """Eq. 3-4 by brute force: the open length along ``angle``, capped at the range."""
    c, s = math.cos(angle), math.sin(angle)
    best = CFG.max_range_m
    for x, y in points:
        along, lateral = x * c + y * s, -x * s + y * c
        if along > 0 and abs(lateral) < R:
            best = min(best, along - R)
    return max(best, 0.0)


@settings(max_examples=60, deadline=None)
@given(
    pts=st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), min_size=0, max_size=12),
    vx=st.floats(-1, 1),
    vy=st.floats(-1, 1),
    w=st.floats(-2, 2),
    hold=st.floats(0, 0.5),
)
def test_the_choice_is_the_nearest_safe_velocity_and_stops_short_of_the_exact_contact(pts, vx, vy, w, hold) -> None:
    """The filtered velocity stops short of the first contact along its sweep (Eq. 4 is
    conservative against the exact disc) and keeps the turn rate; no velocity along the
    command's direction or the fan's, at most that direction's safe speed (Eq. 4 and the
    braking law by brute force, speeds on a grid and the projection), is nearer the command."""
    points = np.array(pts, dtype=np.float64).reshape(-1, 2)
    points = points[np.hypot(points[:, 0], points[:, 1]) > R]  # not already inside the disc
    cmd = np.array([vx, vy, w])
    out = safe_command(cmd, points, hold, CFG)
    assert out[2] == w
    v = math.hypot(out[0], out[1])
    if v > 0:
        assert stops_in_time(v, math.atan2(out[1], out[0]), w, hold, points)
    speed, heading = math.hypot(vx, vy), math.atan2(vy, vx)
    if speed == 0:
        assert np.array_equal(out, cmd)
        return
    got = math.hypot(*(out[:2] - cmd[:2]))
    best = speed  # standing still
    for k in range(FAN_DIRECTIONS):
        a = heading + 2 * math.pi * k / FAN_DIRECTIONS
        d = min(eq4_open_m(points, b) for b in np.linspace(a, a + w * hold, SWEEP_SAMPLES))
        limit = braking_speed(d, hold, CFG.max_decel_mps2, CFG.stop_distance_m)
        s = np.append(np.linspace(0.0, limit, 50), min(max(speed * math.cos(a - heading), 0.0), limit))
        best = min(best, float(np.hypot(vx - s * math.cos(a), vy - s * math.sin(a)).min()))
    assert got <= best + 1e-9
    assert got >= best - 1e-9


def test_bad_arguments_are_one_line_errors() -> None:
    with pytest.raises(InputError, match="safe_command"):
        safe_command(np.array([1.0, np.nan, 0.0]), np.zeros((0, 2)), 0.2)
    with pytest.raises(InputError, match="hold_s"):
        safe_command(np.zeros(3), np.zeros((0, 2)), -1.0)
