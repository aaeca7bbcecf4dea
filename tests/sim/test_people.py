"""The people model: polite, kinematic pedestrians (sim/actors.py PeopleController)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.actors import PeopleController, Person

DT = 1.0 / 30.0


def _walk(people: tuple[Person, ...], robot_path, steps: int) -> np.ndarray:
    """Positions (steps + 1, n, 2) of the people while the robot follows ``robot_path(k)``."""
    pc = PeopleController(people, np.zeros(len(people), dtype=int))
    out = [pc.positions()[:, :2]]
    for k in range(1, steps + 1):
        out.append(pc.advance(k * DT, robot_path(k))[:, :2])
    return np.array(out)


def test_a_person_stepped_aside_does_not_jump_where_the_route_turns() -> None:
    """An L-shaped route with the robot standing near its corner: the person steps aside
    and is still aside at the corner, where the offset point of the next leg lies
    elsewhere; the person walks there instead of teleporting (a jump put a person right
    in front of the robot in the 4 km run)."""
    p = Person(route=((0.0, 0.0), (6.0, 0.0), (6.0, -6.0)), speed_mps=0.75)
    robot = lambda k: np.array([7.0, 0.3])  # noqa: E731 - just past the corner, ahead
    pos = _walk((p,), robot, 360)
    steps = np.hypot(*np.diff(pos[:, 0], axis=0).T)
    reach = (p.speed_mps + PeopleController.side_speed_mps) * DT
    assert steps.max() <= reach + 1e-9
    assert pos[-1, 0, 1] < -2.5  # and still gets round the corner and down the second leg


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0),
    st.floats(0.3, 1.5), st.booleans(),
)
def test_people_never_walk_into_the_robot(rx: float, ry: float, vx: float, vy: float, speed: float, loop: bool) -> None:
    """Whatever the robot does, no step of a person brings them closer than the personal
    space to it (their own motion; a robot that drives into someone still collides)."""
    people = (
        Person(route=((-4.0, 0.0), (4.0, 0.0), (4.0, 3.0)), speed_mps=speed, loop=loop),
        Person(route=((0.0, -4.0), (0.0, 4.0)), speed_mps=speed, start_offset_m=2.0),
    )
    pc = PeopleController(people, np.zeros(2, dtype=int))
    keep = pc.robot_radius_m + people[0].radius_m + pc.personal_space_m
    prev = pc.positions()[:, :2]
    for k in range(1, 300):
        robot = np.array([rx + vx * k * DT, ry + vy * k * DT])
        cur = pc.advance(k * DT, robot)[:, :2]
        d_new = np.hypot(*(cur - robot).T)
        d_old = np.hypot(*(prev - robot).T)
        moved = np.hypot(*(cur - prev).T) > 1e-12
        assert not np.any(moved & (d_new < keep - 1e-9) & (d_new < d_old - 1e-9))
        prev = cur
