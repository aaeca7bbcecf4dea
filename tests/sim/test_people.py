"""The people model: polite, kinematic pedestrians (sim/actors.py PeopleController)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from autonomy.common.geometry import point_segment_distance
from sim.simulator.actors import PeopleController, Person
from sim.simulator.blueprints import load_blueprint
from sim.simulator.world import build_world

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
    elsewhere; the person walks there instead of teleporting (a jump can put a person
    right in front of the robot)."""
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


def test_a_person_steps_back_from_a_slow_robot_but_not_from_a_fast_one() -> None:
    """A person standing in the open; the robot drives straight at them. At 0.3 m/s
    (slower than the 0.5 m/s step back) they step aside and back and are never touched;
    at 2 m/s the robot catches up (contact is the robot's doing, and counted)."""
    person = Person(route=((0.0, 0.0), (0.01, 0.0)), speed_mps=0.0)
    pc_r = PeopleController((person,), np.zeros(1, dtype=int))
    touch = pc_r.robot_radius_m + person.radius_m
    for speed, caught in ((0.3, False), (2.0, True)):
        pc = PeopleController((person,), np.zeros(1, dtype=int))
        gaps = []
        for k in range(1, 240):
            robot = np.array([-2.0 + speed * k * DT, 0.05])
            cur = pc.advance(k * DT, robot)[0, :2]
            gaps.append(float(np.hypot(*(cur - robot))) - touch)
        assert (min(gaps) <= 0.0) == caught, (speed, min(gaps))
        if not caught:
            assert min(gaps) > 0.1


def test_a_person_does_not_step_back_into_a_wall_or_from_a_robot_standing_still() -> None:
    walls = np.array([[-5.0, 0.3, 5.0, 0.3]])  # a wall right behind (north of) the person
    person = Person(route=((0.0, 0.0), (0.01, 0.0)), speed_mps=0.0)
    pc = PeopleController((person,), np.zeros(1, dtype=int), walls)
    for k in range(1, 60):  # robot comes from the south at 0.3 m/s and stops 0.6 m away
        robot = np.array([0.0, max(-1.5 + 0.3 * k * DT, -0.6)])
        cur = pc.advance(k * DT, robot)[0, :2]
    assert abs(cur[1]) < 1e-9 or cur[1] < 0.3 - person.radius_m - pc.squeeze_m + 1e-9  # 1 cm from it at most
    still = PeopleController((person,), np.zeros(1, dtype=int))
    for k in range(1, 60):  # a robot standing 0.28 m from their body (outside personal space)
        cur = still.advance(k * DT, np.array([0.0, -0.8]))[0, :2]
    np.testing.assert_allclose(cur, [0.0, 0.0], atol=1e-12)


def test_a_person_touched_by_a_standing_robot_steps_out_of_its_personal_space() -> None:
    """The robot stopped (turning in place) with a person touching its front: the person
    steps back until the personal space is restored, then stands (else a person pinned
    like this stays touching the robot while it turns and backs off)."""
    person = Person(route=((0.0, 0.0), (0.01, 0.0)), speed_mps=0.0)
    pc = PeopleController((person,), np.zeros(1, dtype=int))
    robot = np.array([0.0, -(pc.robot_radius_m + person.radius_m)])
    pos = np.array([pc.advance(k * DT, robot)[0, :2] for k in range(1, 90)])
    gaps = np.hypot(*(pos - robot).T) - pc.robot_radius_m - person.radius_m
    assert gaps[15] > 0.1  # stepping back at 0.5 m/s: 0.25 m in half a second, minus the first step
    assert gaps.min() >= 0.0 and np.all(np.diff(gaps) >= -1e-9)  # never towards the robot
    assert gaps[-1] >= pc.personal_space_m and np.ptp(pos[-10:], axis=0).max() < 1e-9  # out of it, and standing


def test_a_person_overtakes_a_robot_instead_of_walking_abeam_of_it() -> None:
    """A faster person walking up behind the robot on the same line steps aside and
    passes it, and is ahead (where the camera sees) a few seconds later, not held abeam
    of it, just out of its camera's view, where its next turn drives into them."""
    person = Person(route=((-3.0, 0.0), (40.0, 0.0)), speed_mps=1.3)
    robot = lambda k: np.array([0.75 * k * DT, 0.02 * np.sin(0.5 * k * DT)])  # noqa: E731 - 0.75 m/s, weaving by 2 cm
    pos = _walk((person,), robot, 600)
    rel = pos[:, 0] - np.array([robot(k) for k in range(601)])
    touch = PeopleController.robot_radius_m if hasattr(PeopleController, "robot_radius_m") else 0.3
    assert np.hypot(rel[:, 0], rel[:, 1]).min() > touch + person.radius_m + 0.1
    abeam = np.abs(rel[:, 0]) < 0.5
    assert abeam.sum() * DT < 2.0  # passing takes ~1 s at the 0.55 m/s difference
    assert rel[-1, 0] > 2.0  # well ahead of the robot 20 s later


def test_a_person_who_cannot_step_back_along_their_route_steps_sideways() -> None:
    """A person facing away from a robot backing slowly at them along their route (a
    recovery back-off), with a wall right behind them across the route: stepping back
    along the route is impossible, so they step sideways and are never touched rather
    than stand still where the robot drives into them."""
    person = Person(route=((0.0, 0.0), (5.0, 0.0)), speed_mps=0.0, start_offset_m=8.0)  # at x = 2, facing -x
    walls = np.array([[1.72, -0.3, 1.72, 0.3]])
    pc = PeopleController((person,), np.zeros(1, dtype=int), walls)
    touch = pc.robot_radius_m + person.radius_m
    gaps = []
    for k in range(1, 300):
        robot = np.array([max(3.5 - 0.15 * k * DT, 2.3), 0.0])  # stops where it would overlap them
        gaps.append(float(np.hypot(*(pc.advance(k * DT, robot)[0, :2] - robot))) - touch)
    assert min(gaps) > 0.05, min(gaps)
    assert abs(pc.positions()[0, 1]) > 0.3  # stepped sideways


def test_a_person_stepped_aside_turns_round_on_the_spot_at_the_route_end() -> None:
    """A person passes a robot standing near the end of their back-and-forth route,
    stepped aside to their left, and turns round at the end: they stay on the same side
    of the corridor (now their right) instead of walking diagonally across to the
    mirrored offset, which can lead them into a robot standing there and hold both in
    a deadlock."""
    p = Person(route=((0.0, 0.0), (3.0, 0.0)), speed_mps=1.0)
    robot = lambda k: np.array([2.6, -0.5])  # noqa: E731 - standing, right of the route's end
    pos = _walk((p,), robot, 150)[:, 0]
    end = int(np.argmax(pos[:, 0]))
    assert pos[end, 0] > 2.9 and pos[end, 1] > 0.7  # reached the end, stepped aside to the left
    around = pos[max(0, end - 30) : end + 30]
    assert around[:, 1].min() > 0.7  # no walk across the corridor at the turn
    pc = PeopleController((p,), np.zeros(1, dtype=int))
    assert np.hypot(*(pos - robot(0)).T).min() > pc.robot_radius_m + p.radius_m + pc.personal_space_m - 1e-9


def test_a_person_held_up_by_a_robot_in_a_narrow_corridor_turns_back() -> None:
    """A robot standing in the middle of a 1.2 m corridor blocks a person's route: the
    person waits (personal space) and after ``max_blocked_s`` turns back, instead of
    standing in front of the robot for ever (a deadlock, as in a doorway).
    """
    walls = np.array([[-1.0, -0.6, 12.0, -0.6], [-1.0, 0.6, 12.0, 0.6]])
    p = Person(route=((0.0, 0.0), (10.0, 0.0)), speed_mps=1.0)
    pc = PeopleController((p,), np.zeros(1, dtype=int), walls)
    robot = np.array([5.0, 0.0])
    keep = pc.robot_radius_m + p.radius_m + pc.personal_space_m
    xs = []
    for k in range(1, 20 * 30):
        cur = pc.advance(k * DT, robot)[0, :2]
        assert np.hypot(*(cur - robot)) > keep - 1e-9
        xs.append(cur[0])
    xs = np.array(xs)
    stop = int(np.argmax(xs))
    assert xs[stop] > 4.0  # came up to the robot ...
    assert xs[stop] < 5.0  # ... never past it ...
    assert xs[stop:].min() < 1.0  # ... and walked back to the route's start
    held = np.sum(np.abs(xs[: stop + 200] - xs[stop]) < 1e-6) * DT
    assert PeopleController.max_blocked_s <= held < PeopleController.max_blocked_s + PeopleController.max_wait_s + 1.5


def test_a_person_tailing_a_slowly_backing_robot_in_a_narrow_corridor_turns_back() -> None:
    """A robot backs at 0.15 m/s along a 1.2 m corridor, the way a faster person walks:
    the person comes up behind it, cannot pass, and is held up at the personal space
    (each step waits for the robot to make room); after ``max_blocked_s`` they turn back
    rather than tail it in the camera's blind zone, where the robot, driving forward
    again, hits the person it cannot see."""
    walls = np.array([[-1.0, -0.6, 30.0, -0.6], [-1.0, 0.6, 30.0, 0.6]])
    p = Person(route=((0.0, 0.0), (25.0, 0.0)), speed_mps=1.0)
    pc = PeopleController((p,), np.zeros(1, dtype=int), walls)
    xs, gaps = [], []
    for k in range(1, 20 * 30):
        robot = np.array([6.0 + 0.15 * k * DT, 0.0])
        cur = pc.advance(k * DT, robot)[0, :2]
        xs.append(cur[0])
        gaps.append(float(np.hypot(*(cur - robot))) - pc.robot_radius_m - p.radius_m)
    xs = np.array(xs)
    assert min(gaps) > 0.05
    turn = int(np.argmax(xs))
    tailing = np.sum(np.array(gaps[:turn]) < pc.personal_space_m + pc.clear_of_robot_m) * DT
    assert tailing < pc.max_wait_s + pc.max_blocked_s + 1.0  # held up for a few seconds at most ...
    assert xs[-1] < xs[turn] - 5.0  # ... then walking back the other way


def test_a_person_does_not_step_into_the_path_of_a_moving_robot() -> None:
    """A person walking across the corridor towards the line a robot drives along waits
    at its edge until the robot has passed: never within a metre ahead of it, in its
    path (the camera's blind zone). Keeping clear of where the robot is, not where it
    will be, would let them cross 0.7 m in front of it."""
    robot = lambda k: np.array([-4.0 + 0.5 * k * DT, 0.0])  # noqa: E731 - 0.5 m/s along y = 0
    for offset in (0.375, 0.5, 0.75, 1.0, 1.25, 1.5):
        person = Person(route=((0.0, -3.0), (0.0, 3.0)), speed_mps=1.0, start_offset_m=offset)
        pos = _walk((person,), robot, 480)
        rel = pos[:, 0] - np.array([robot(k) for k in range(481)])
        in_path = (rel[:, 0] > 0.0) & (rel[:, 0] < 1.0) & (np.abs(rel[:, 1]) < 0.3 + person.radius_m)
        assert not in_path.any(), offset
        assert pos[:, 0, 1].max() > 1.0  # and crosses once it has passed


def test_a_person_a_robot_drives_at_steps_out_of_its_way() -> None:
    """A person standing on a robot's line steps sideways out of its path, not back along
    it (stepping straight back, they would be pushed along ahead of it, out of its view)."""
    person = Person(route=((2.0, -3.0), (2.0, 3.0)), speed_mps=0.0, start_offset_m=3.0)
    robot = lambda k: np.array([0.3 * k * DT, 0.0])  # noqa: E731 - 0.3 m/s at them
    pos = _walk((person,), robot, 400)
    assert abs(pos[-1, 0, 0] - 2.0) < 0.05 and abs(pos[-1, 0, 1]) > 0.6


def test_a_person_passes_a_moving_robot_with_room_to_spare() -> None:
    """Overtaking a robot on the move, a person keeps pass_gap_m from it, not just the
    personal space (passing 5 cm abeam, out of the camera's view, they would be in the
    way of the robot's next turn); from a robot standing still the personal space is
    enough."""
    person = Person(route=((-3.0, 0.0), (40.0, 0.0)), speed_mps=1.3)
    robot = lambda k: np.array([0.4 * k * DT, 0.0])  # noqa: E731 - 0.4 m/s along the route
    pos = _walk((person,), robot, 600)
    rel = pos[:, 0] - np.array([robot(k) for k in range(601)])
    pc = PeopleController((person,), np.zeros(1, dtype=int))
    assert np.hypot(rel[:, 0], rel[:, 1]).min() >= pc.robot_radius_m + person.radius_m + pc.pass_gap_m - 0.02
    assert rel[-1, 0] > 2.0  # and gets past


def test_a_person_wedged_at_a_door_frame_squeezes_along_the_wall_out_of_the_robots_way() -> None:
    """A person standing 26 cm from a door frame's end (within the 5 cm wall margin of
    every step away) while a robot turns towards the door, into them: they squeeze along
    the wall, 1 cm from it, and are never touched. Keeping the 5 cm, they would stand
    still while the robot, which cannot see them, drives into them."""
    walls = np.array([[0.0, -1.0, 0.0, 0.0], [0.0, 0.93, 0.0, 1.8]])  # a door from y = 0 to 0.93
    person = Person(route=((0.258, -3.0), (0.258, 3.0)), speed_mps=0.0, start_offset_m=3.038)
    pc = PeopleController((person,), np.zeros(1, dtype=int), walls)
    heading = np.radians(146.0)
    robot = lambda k: np.array([0.93, 0.02]) + 0.3 * k * DT * np.array([np.cos(heading), np.sin(heading)])  # noqa: E731
    touch = pc.robot_radius_m + person.radius_m
    gaps, wall = [], []
    for k in range(1, 90):
        pos = pc.advance(k * DT, robot(k))[0, :2]
        gaps.append(float(np.hypot(*(pos - robot(k)))) - touch)
        wall.append(float(np.min([np.hypot(pos[0], pos[1] - np.clip(pos[1], a, b)) for a, b in ((-1.0, 0.0), (0.93, 1.8))])))
    assert min(gaps) > 0.0, min(gaps)
    assert min(wall) > person.radius_m + pc.squeeze_m - 1e-9


def test_a_person_whose_body_overlaps_a_door_frames_end_steps_out_of_the_robots_way() -> None:
    """A person who followed the robot to a door, held up there by it, stands with their
    body 17 cm from the end of the door's frame (inside it: people are not stopped by
    walls, and a body that lags its route position can end there) when the robot comes
    back out through the door at 0.38 m/s: they step back, no deeper into the frame, and
    are never touched. With every step held to the walls' margin none is taken, and they
    stand while the robot, which cannot see them beside it, drives into them (as at a door
    on a 4 km run)."""
    walls = np.array([[-0.938, 0.0, 0.0, 0.0], [0.987, 0.0, 1.87, 0.0]])  # a door from x = 0 to 0.987
    person = Person(route=((0.494, -0.75), (0.494, 1.075), (2.157, 1.075)), speed_mps=1.38)
    pc = PeopleController((person,), np.zeros(1, dtype=int), walls)
    pc._s[0], pc._side[0] = 0.67, -0.22  # white box: their route position in the door ...
    pc._state[0] = pc._place(0)
    pc._state[0, :2] = (0.055, 0.162)  # ... their body lagging it, by the frame's end
    start, heading = np.array([0.445, -0.451]), np.radians(85.0)
    robot = lambda k: start + 0.38 * k * DT * np.array([np.cos(heading), np.sin(heading)])  # noqa: E731
    touch = pc.robot_radius_m + person.radius_m
    pc.advance(0.0, start)
    gaps, frame = [], []
    for k in range(1, 150):
        pos = pc.advance(k * DT, robot(k))[0, :2]
        gaps.append(float(np.hypot(*(pos - robot(k)))) - touch)
        frame.append(float(point_segment_distance(pos, walls).min()))
    assert min(gaps) > 0.0, min(gaps)
    assert min(frame) >= frame[0] - 1e-9  # never deeper into the frame


def _gaps_to_a_robot_driving_at(pc: PeopleController, start_xy: np.ndarray, bearing: float, speed: float, steps: int) -> list[float]:
    """Gaps between person 0's body and a robot that starts 1 m from ``start_xy`` (at
    ``bearing``) and drives straight through that point at ``speed``."""
    touch = pc.robot_radius_m + pc.people[0].radius_m
    r0 = start_xy + np.array([np.cos(bearing), np.sin(bearing)])
    u = -np.array([np.cos(bearing), np.sin(bearing)])
    gaps = []
    for k in range(1, steps):
        robot = r0 + speed * k * DT * u
        gaps.append(float(np.hypot(*(pc.advance(k * DT, robot)[0, :2] - robot))) - touch)
    return gaps


@settings(max_examples=40, deadline=None)
@given(
    walking=st.booleans(),
    offset=st.floats(2.0, 4.0),
    side=st.floats(-0.95, 0.95),
    lag_x=st.floats(-0.4, 0.4),
    lag_y=st.floats(-0.4, 0.4),
    bearing=st.floats(0.0, 2 * np.pi),
    speed=st.floats(0.1, 0.4),
)
@example(walking=False, offset=3.901, side=-0.676, lag_x=0.359, lag_y=-0.151, bearing=np.radians(152.4), speed=0.223)
def test_a_person_whose_body_lags_their_route_still_steps_out_of_the_robots_way(
    walking: bool, offset: float, side: float, lag_x: float, lag_y: float, bearing: float, speed: float
) -> None:
    """Round a route's corner stepped aside, a person's body walks to the next leg's
    offset (it lags their route position). A robot driving at them then (at most 0.4
    m/s, open floor) never touches them. Were every step back measured from the route
    position, it would be a jump and not taken: they would stand while a backing robot
    drives into them."""
    person = Person(route=((0.0, 3.0), (0.0, 0.0), (-3.0, 0.0)), speed_mps=1.0 if walking else 0.0, start_offset_m=offset)
    pc = PeopleController((person,), np.zeros(1, dtype=int))
    pc._side[0] = side  # white box: stepped aside, the body off its route position
    pc._state[0] = pc._place(0)
    pc._state[0, :2] += (lag_x, lag_y)
    gaps = _gaps_to_a_robot_driving_at(pc, pc._state[0, :2].copy(), bearing, speed, 150)
    assert min(gaps) > 0.0, min(gaps)


@settings(max_examples=40, deadline=None)
@given(side=st.floats(-0.7, 0.7), lateral=st.floats(-0.6, 0.6), speed=st.floats(0.1, 0.4), forward=st.booleans())
@example(side=-0.676, lateral=0.577, speed=0.317, forward=True)
def test_a_person_beside_a_wall_gets_out_of_the_way_of_a_robot_driving_along_it(side: float, lateral: float, speed: float, forward: bool) -> None:
    """In a 2 m corridor a robot drives along at up to 0.4 m/s on a line where a person
    stands: the person gets out of its way (sideways, or along the corridor at the full
    0.5 m/s where the wall is beside them), never touched. Taking only the along-route
    part of their step back beside the wall, 0.2 m/s, the robot would catch them up."""
    walls = np.array([[-6.0, -1.0, 6.0, -1.0], [-6.0, 1.0, 6.0, 1.0]])
    person = Person(route=((-5.0, 0.0), (5.0, 0.0)), speed_mps=0.0, start_offset_m=5.0)
    pc = PeopleController((person,), np.zeros(1, dtype=int), walls)
    pc._side[0] = side  # white box: standing stepped aside
    pc._state[0] = pc._place(0)
    start = np.array([pc._state[0, 0], lateral])
    gaps = _gaps_to_a_robot_driving_at(pc, start, 0.0 if not forward else np.pi, speed, 200)
    assert min(gaps) > 0.0, min(gaps)


def test_a_person_waiting_in_a_doorway_gets_out_of_the_way_of_a_robot_turning_into_the_door() -> None:
    """A person stepped aside into a doorway, 27 cm from the end of its frame, and a
    robot turns into the door: every one of the three preferred steps back leads towards
    the frame, so they step the way that is open (into the door, ahead of the robot),
    never touched rather than stand where the robot, which cannot see them beside it,
    drives into them."""
    walls = np.array([[0.0, -2.0, 0.0, 0.0], [0.0, 0.96, 0.0, 3.0], [2.0, -2.0, 2.0, 3.0]])  # door at x = 0, y 0-0.96
    person = Person(route=((1.0, -2.0), (1.0, 3.0)), speed_mps=0.0, start_offset_m=2.235)
    pc = PeopleController((person,), np.zeros(1, dtype=int), walls)
    pc._side[0] = -0.859  # white box: stepped aside to the left, into the doorway
    pc._state[0] = pc._place(0)
    # A robot's track turning into the door (relative to the frame's end): north, then
    # curving left into the door, at 0.4 m/s.
    track = np.array([[1.0, -0.35], [0.95, 0.0], [0.85, 0.15], [0.58, 0.28], [-0.4, 0.5]])
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(track, axis=0).T))])
    touch = pc.robot_radius_m + person.radius_m
    gaps = []
    for k in range(1, 150):
        s = min(0.4 * k * DT, cum[-1])
        robot = np.array([np.interp(s, cum, track[:, 0]), np.interp(s, cum, track[:, 1])])
        gaps.append(float(np.hypot(*(pc.advance(k * DT, robot)[0, :2] - robot))) - touch)
    assert min(gaps) > 0.0, min(gaps)


def test_a_person_walking_on_stepped_aside_keeps_off_the_walls_where_the_corridor_narrows() -> None:
    """Stepped aside 0.95 m in an open area, a person walks on into a 2 m corridor: their
    offset shrinks so that they keep 5 cm off its wall. At 0.95 m they would walk through
    the wall (people are not stopped by walls), or wait half inside a door frame's end,
    where no step back is clear of it."""
    walls = np.array([[3.0, -1.0, 12.0, -1.0], [3.0, 1.0, 12.0, 1.0]])
    person = Person(route=((0.0, 0.0), (12.0, 0.0)), speed_mps=1.0, start_offset_m=1.0)
    pc = PeopleController((person,), np.zeros(1, dtype=int), walls)
    pc.notice_m = 20.0  # they see the robot down the corridor from the start
    pc._side[0] = 0.95  # white box: stepped aside (to the right, -y) in the open area
    pc._state[0] = pc._place(0)
    assert pc._state[0, 1] == pytest.approx(-0.95)
    robot = np.array([11.8, 0.3])  # standing at the corridor's end, left of the route
    for k in range(1, 240):
        pos = pc.advance(k * DT, robot)[0, :2]
        if pos[0] > 3.5:
            assert abs(pos[1]) <= 1.0 - person.radius_m - 0.05 + 1e-9, pos
    assert pos[0] > 8.0  # and walked on


def test_a_person_who_would_start_on_the_robot_starts_further_along_their_route() -> None:
    """Start offsets are drawn without knowing where the robot starts. A person placed on
    the robot moves on along the route until clear of it; others keep their start, and a
    route that never leaves the robot's surroundings keeps its offset."""
    on = Person(route=((0.0, 0.0), (8.0, 0.0)), start_offset_m=3.0)
    far = Person(route=((0.0, 5.0), (8.0, 5.0)), start_offset_m=3.0)
    short = Person(route=((2.9, 0.1), (3.1, 0.1)), start_offset_m=0.1)
    robot = np.array([3.0, 0.1])
    pc = PeopleController((on, far, short), np.zeros(3, dtype=int))
    pc.reset(robot)
    pos = pc.positions()[:, :2]
    gap = pc.robot_radius_m + on.radius_m + pc.clear_of_robot_m
    assert gap <= np.hypot(*(pos[0] - robot)) < gap + 0.25 + 1e-9 and pos[0, 0] > robot[0]
    np.testing.assert_allclose(pos[1], [3.0, 5.0])
    np.testing.assert_allclose(pos[2], [3.0, 0.1])
    # Without the robot's position the offsets are the people's own.
    pc.reset()
    np.testing.assert_allclose(pc.positions()[0, :2], [3.0, 0.0])


def test_a_world_with_a_person_drawn_on_the_robots_start_does_not_shove_the_robot() -> None:
    """The world puts people clear of the robot's start pose: standing still for a
    second, the robot neither moves nor touches anyone."""
    start = (12.0, 6.3, 0.0)
    person = Person(route=((8.0, 6.3), (16.0, 6.3)), start_offset_m=4.0, speed_mps=0.0)
    world = build_world(load_blueprint("corridor_loop").vectormap, people=(person,), start_pose=start)
    substeps = round(DT / world.model.opt.timestep)
    contacts = 0
    for k in range(30):
        world.robot.command(world.data, np.zeros(3), DT)
        world.people.update(world.data, (k + 1) * DT, np.array(start[:2]))
        contacts += world.step_frame(substeps)
    pose = world.robot.pose(world.data)
    assert np.hypot(pose[0] - start[0], pose[1] - start[1]) < 0.01, pose
    assert contacts == 0 and not world.collision_log


def test_body_names_are_made_and_read_back_in_one_place() -> None:
    from sim.simulator.actors import furniture_body, person_body, person_index

    assert furniture_body(3) == "furniture_3" and person_body(12) == "person_12"
    assert person_index(person_body(12)) == 12
    assert person_index(furniture_body(3)) is None and person_index("person_") is None and person_index("person_x") is None


def test_a_person_pressed_against_a_wall_slides_along_it_out_of_the_robots_way() -> None:
    """A person who followed the robot into a corridor stands 1 cm from the corridor's wall
    (a real floor: NSH2 of the ut-amrl/amrl_maps collection, BSD) when the robot, which
    never saw them, backs off along its trail towards them at a slant, at 0.15 m/s: every
    step of the 30 degree fan either goes into the wall or comes nearer the robot, so
    they slide along the wall, and are never touched. Without the slide they stand still
    until the robot drives into them."""
    walls = np.array(
        [
            [27.631, 47.486, 27.631, 37.464],
            [27.902, 37.825, 27.902, 47.486],
            [27.541, 47.486, 27.541, 47.847],
            [27.902, 47.486, 30.34, 47.486],
            [27.541, 47.847, 30.34, 47.847],
            [26.547, 47.486, 26.547, 47.847],
            [22.034, 47.486, 26.547, 47.486],
        ]
    )
    route = ((26.729, 38.742), (26.629, 42.542), (26.529, 46.342), (27.029, 46.992), (27.029, 48.692))
    person = Person(route=route, speed_mps=1.0)
    pc = PeopleController((person,), np.zeros(1, dtype=int), walls)
    pc._s[0], pc._side[0] = 8.414, 0.457  # 0.54 m past the route's corner, stepped aside to its right ...
    pc._state[0, :2] = (27.399, 46.753)  # ... pressed against the wall: 0.232 m from its line
    start, v0, v1 = np.array([26.681, 46.664]), np.array([0.054, 0.138]), np.array([0.126, 0.084])

    def robot(k: int) -> np.ndarray:
        """The back-off: its direction turns from v0 to v1 over the first 0.4 s."""
        t = k * DT
        a = min(t, 0.4)
        return start + v0 * a + (v1 - v0) * a * a / 0.8 + v1 * max(t - 0.4, 0.0)

    touch = pc.robot_radius_m + person.radius_m
    pc.advance(0.0, start)
    gaps, wall = [], []
    for k in range(1, 75):
        pos = pc.advance(k * DT, robot(k))[0, :2]
        gaps.append(float(np.hypot(*(pos - robot(k)))) - touch)
        wall.append(float(point_segment_distance(pos, walls).min()))
    assert min(gaps) > 0.05, min(gaps)
    assert min(wall) >= person.radius_m + pc.squeeze_m - 1e-6
