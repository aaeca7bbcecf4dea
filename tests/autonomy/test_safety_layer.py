"""The safety layer under a velocity command: its braking speed in closed form, and the
stop it promises checked against the exact first contact of a disc with each point."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.navigation.safety import SWEEP_SAMPLES, SafetyLayerConfig, braking_speed, safe_command

CFG = SafetyLayerConfig(robot_radius_m=0.25, safety_margin_m=0.05, max_decel_mps2=1.0, stop_distance_m=0.05, max_range_m=4.0)


def exact_contact_m(points: np.ndarray, angle: float, radius: float) -> float:
    """How far a disc of ``radius`` moves along ``angle`` before it touches a point (brute force)."""
    c, s = math.cos(angle), math.sin(angle)
    best = math.inf
    for x, y in points:
        along, lateral = x * c + y * s, -x * s + y * c
        if along > 0 and abs(lateral) < radius:
            best = min(best, along - math.sqrt(radius * radius - lateral * lateral))
    return max(best, 0.0)


def test_braking_speed_travels_then_stops_in_exactly_the_room() -> None:
    for room, hold in [(1.0, 0.2), (0.3, 0.2), (2.5, 0.0), (0.05, 1.0)]:
        v = braking_speed(room + 0.05, hold, 2.0, 0.05)
        assert v * hold + v * v / 4.0 == pytest.approx(room, rel=1e-12)
    assert braking_speed(0.04, 0.2, 1.0, 0.05) == 0.0


def test_nothing_known_leaves_the_command_alone_and_a_wall_ahead_slows_only_the_approach() -> None:
    cmd = np.array([0.75, 0.0, 0.0])
    assert np.array_equal(safe_command(cmd, np.zeros((0, 2)), 0.2, CFG), cmd)
    wall = np.column_stack([np.full(41, 0.6), np.linspace(-2, 2, 41)])
    slowed = safe_command(cmd, wall, 0.2, CFG)
    assert 0 < slowed[0] < 0.75 and slowed[1] == 0.0
    # Moving away from the wall or along it is not slowed; turning in place passes.
    for free in ([-0.75, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 1.2]):
        assert np.array_equal(safe_command(np.array(free), wall, 0.2, CFG), free)
    # Touching it: no approach at all.
    assert safe_command(cmd, wall - [0.3, 0.0], 0.2, CFG)[0] == 0.0


def test_a_turning_command_is_slowed_for_what_its_sweep_reaches() -> None:
    """A post ahead-left is outside the straight corridor but inside the one the command
    turns into while it is held."""
    post = np.array([[0.6, 0.45]])
    cmd = np.array([0.75, 0.0, 0.0])
    assert np.array_equal(safe_command(cmd, post, 0.5, CFG), cmd)
    turning = np.array([0.75, 0.0, 1.5])
    assert safe_command(turning, post, 0.5, CFG)[0] < 0.75


@settings(max_examples=200, deadline=None)
@given(
    pts=st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), min_size=0, max_size=12),
    vx=st.floats(-1, 1),
    vy=st.floats(-1, 1),
    w=st.floats(-2, 2),
    hold=st.floats(0, 0.5),
)
def test_the_promised_stop_is_short_of_the_exact_contact(pts, vx, vy, w, hold) -> None:
    """Travelling the held speed then braking stays short of the first contact along every
    direction of the sweep (Eq. 4 is conservative against the exact disc), and the
    direction and turn rate are kept."""
    points = np.array(pts, dtype=np.float64).reshape(-1, 2)
    r = CFG.robot_radius_m + CFG.safety_margin_m
    points = points[np.hypot(points[:, 0], points[:, 1]) > r]  # not already inside the disc
    cmd = np.array([vx, vy, w])
    out = safe_command(cmd, points, hold, CFG)
    assert out[2] == w
    v = math.hypot(out[0], out[1])
    assert v <= math.hypot(vx, vy) + 1e-12
    if v > 0:
        assert math.atan2(out[1], out[0]) == pytest.approx(math.atan2(vy, vx), abs=1e-9)
        heading = math.atan2(vy, vx)
        reach = min(exact_contact_m(points, a, r) for a in np.linspace(heading, heading + w * hold, SWEEP_SAMPLES))
        assert v * hold + v * v / (2 * CFG.max_decel_mps2) <= min(reach, CFG.max_range_m) - CFG.stop_distance_m + 1e-9


def test_bad_arguments_are_one_line_errors() -> None:
    with pytest.raises(InputError, match="safe_command"):
        safe_command(np.array([1.0, np.nan, 0.0]), np.zeros((0, 2)), 0.2)
    with pytest.raises(InputError, match="hold_s"):
        safe_command(np.zeros(3), np.zeros((0, 2)), -1.0)
    with pytest.raises(InputError, match="safety.max_decel_mps2"):
        SafetyLayerConfig(max_decel_mps2=0.0)
