"""World building: every map segment becomes a wall; contacts are real and counted."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.maps.vectormap import VectorMap
from sim.simulator.actors import Furniture, Person
from sim.simulator.world import WorldConfig, build_world
from tests.helpers import box_room


def test_every_segment_becomes_a_wall_box() -> None:
    rng = np.random.default_rng(3)
    segs = rng.uniform(-20, 20, size=(50, 4))
    vm = VectorMap.from_segments(segs)
    w = build_world(vm, world=WorldConfig(wall_height_m=2.2, wall_thickness_m=0.02), start_pose=(100.0, 100.0, 0.0))
    m = w.model
    for i, s in enumerate(segs):
        gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"wall_{i}")
        assert gid >= 0
        length = math.hypot(s[2] - s[0], s[3] - s[1])
        np.testing.assert_allclose(m.geom_size[gid], [length / 2, 0.01, 1.1], atol=1e-9)
        np.testing.assert_allclose(w.data.geom_xpos[gid], [(s[0] + s[2]) / 2, (s[1] + s[3]) / 2, 1.1], atol=1e-9)
        # The box's long axis lies along the segment: both end points are on its centre line.
        rot = w.data.geom_xmat[gid].reshape(3, 3)
        axis = rot[:, 0]
        d = np.array([s[2] - s[0], s[3] - s[1], 0.0]) / length
        assert abs(abs(axis @ d) - 1.0) < 1e-9
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"wall_{len(segs)}") == -1


def test_robot_hits_wall_and_contact_is_counted() -> None:
    w = build_world(box_room(), start_pose=(5.0, 3.0, 0.0))
    collisions = 0
    for _ in range(30 * 12):  # 12 s at 0.75 m/s: reaches the wall at x = 10
        w.robot.command(w.data, np.array([0.75, 0.0, 0.0]), 1 / 30)
        collisions += w.step_frame(8)
    x = w.robot.pose(w.data)[0]
    assert collisions >= 1
    names = {w.geom_name(g) for g in w.robot_contacts()}
    assert "wall_1" in names
    # It stops at the wall: radius 0.3 m, wall face at 10 - 0.01 m.
    assert 9.6 < x < 9.72
    # The log says where on the robot the contact was: straight ahead.
    assert abs(w.collision_log[0]["bearing_deg"]) < 5.0
    assert w.collision_log[0]["with"] == ["wall"]


def test_contact_bearing_is_in_the_robot_frame() -> None:
    # Facing north (+90 deg), driving along world +x = the robot's right: the wall at
    # x = 10 is hit at bearing -90 deg.
    w = build_world(box_room(), start_pose=(8.0, 3.0, math.pi / 2))
    for _ in range(30 * 5):
        w.robot.command(w.data, np.array([0.0, -0.75, 0.0]), 1 / 30)
        w.step_frame(8)
    ev = w.collision_log[0]
    assert abs(ev["bearing_deg"] + 90.0) < 5.0, ev
    assert abs(ev["heading_deg"] - 90.0) < 5.0, ev


def test_people_and_furniture_collide_but_not_floor() -> None:
    person = Person(route=((6.0, 3.0), (6.0, 3.5)), speed_mps=0.0)
    w = build_world(box_room(), people=(person,), furniture=(Furniture("box", 3.0, 5.0),), start_pose=(4.0, 3.0, 0.0))
    for _ in range(30 * 4):
        w.people.update(w.data, w.data.time)
        w.robot.command(w.data, np.array([0.5, 0.0, 0.0]), 1 / 30)
        w.step_frame(8)
    bodies = {mujoco.mj_id2name(w.model, mujoco.mjtObj.mjOBJ_BODY, w.model.geom_bodyid[g]) for g in w.robot_contacts()}
    assert bodies == {"person_0"}
    # Stopped by the person: 0.22 m body radius + 0.3 m robot radius.
    assert w.robot.pose(w.data)[0] < 6.0 - 0.22 - 0.3 + 0.05
    # Standing still in the open: no contact with the floor.
    w2 = build_world(box_room(), start_pose=(5.0, 3.0, 0.0))
    w2.step_frame(50)
    assert w2.robot_contacts() == []


def test_speed_limits_hold() -> None:
    w = build_world(box_room(40, 40), start_pose=(5.0, 5.0, 0.0))
    for _ in range(60):
        w.robot.command(w.data, np.array([5.0, 5.0, 9.0]), 1 / 30)
        w.step_frame(8)
    v = w.robot.velocity_body(w.data)
    assert math.hypot(v[0], v[1]) <= w.robot.cfg.max_speed_mps * 1.02
    assert abs(v[2]) <= w.robot.cfg.max_angular_rad_s * 1.02
    assert math.hypot(v[0], v[1]) > 0.7 * w.robot.cfg.max_speed_mps


def test_acceleration_limit_holds() -> None:
    w = build_world(box_room(40, 40), start_pose=(5.0, 5.0, 0.0))
    w.robot.command(w.data, np.array([0.75, 0.0, 0.0]), 1 / 30)
    w.step_frame(8)
    v = w.robot.velocity_body(w.data)
    assert v[0] <= w.robot.cfg.max_accel_mps2 * (1 / 30) * 1.05


def test_large_map_compiles_and_steps() -> None:
    rng = np.random.default_rng(0)
    # 9,000 short walls on a 100 x 100 m grid of rooms.
    p0 = rng.uniform(0, 100, size=(9000, 2))
    ang = rng.uniform(0, np.pi, 9000)
    segs = np.column_stack([p0, p0 + 1.5 * np.column_stack([np.cos(ang), np.sin(ang)])])
    w = build_world(VectorMap.from_segments(segs), start_pose=(-3.0, -3.0, 0.0))
    assert w.model.ngeom >= 9001
    w.robot.command(w.data, np.array([0.5, 0.0, 0.0]), 1 / 30)
    w.step_frame(8)
    assert np.isfinite(w.data.qpos).all()


def test_bad_world_config_is_a_clear_error() -> None:
    with pytest.raises(InputError, match="wall_height_m"):
        WorldConfig(wall_height_m=-1.0)
