"""A long run's mission: when it ends, and when it goes on past its distance."""

from __future__ import annotations

import numpy as np

from sim.experiments.site import load_building
from sim.experiments.waypoints import close_leg, plan_mission
from sim.scenario import SCENARIOS_DIR, MissionConfig, load_scenario


def _mission(target_m: float):
    graph = load_building(load_scenario(SCENARIOS_DIR / "demo.toml")).navgraph
    cfg = MissionConfig(n_random_waypoints=1, target_distance_m=target_m)
    return cfg, graph, plan_mission(cfg, graph, np.random.default_rng(3))


def _close(cfg, graph, mission, distance_m: float, recovering: bool) -> None:
    close_leg(
        mission, cfg, graph, arrived=False, timed_out=True, truth_xy=np.zeros(2), t=10.0, distance_m=distance_m,
        arrival_radius_m=0.3, rng=np.random.default_rng(0), recovering=recovering,
    )


def test_a_run_past_its_distance_ends_at_its_next_waypoint():
    cfg, graph, mission = _mission(100.0)
    _close(cfg, graph, mission, 150.0, recovering=False)
    assert mission.done and mission.failed == 1


def test_a_run_short_of_its_distance_draws_another_waypoint():
    cfg, graph, mission = _mission(100.0)
    _close(cfg, graph, mission, 50.0, recovering=False)
    assert not mission.done and mission.goal != mission.waypoints[0]


def test_a_recovery_under_way_keeps_the_run_going_past_its_distance():
    cfg, graph, mission = _mission(100.0)
    _close(cfg, graph, mission, 150.0, recovering=True)
    assert not mission.done
    _close(cfg, graph, mission, 160.0, recovering=False)
    assert mission.done and mission.failed == 2


def test_a_mission_without_a_distance_ends_with_its_waypoints_even_when_recovering():
    cfg, graph, mission = _mission(0.0)
    _close(cfg, graph, mission, 150.0, recovering=True)
    assert mission.done


def _leg(**kw) -> tuple:
    from sim.experiments.waypoints import Mission, start_leg

    m = MissionConfig(kind="waypoints", target_distance_m=0.0, **kw)
    mission = Mission(waypoints=[1, 2], start_pose=np.zeros(3))
    start_leg(mission, m, 30.0, [1, 5, 2], 10.0, 1.0)
    return m, mission


def test_a_leg_budget_is_the_automatic_timeout_of_its_plan():
    from sim.experiments.waypoints import LEG_TIMEOUT_BASE_S, LEG_TIMEOUT_FACTOR

    _, mission = _leg()
    assert mission.started_at == 10.0
    assert mission.timeout_s == mission.first_timeout_s == LEG_TIMEOUT_BASE_S + LEG_TIMEOUT_FACTOR * 30.0


def test_a_detour_rearms_the_budget_with_what_is_left_of_the_new_plan():
    from sim.experiments.waypoints import LEG_TIMEOUT_BASE_S, LEG_TIMEOUT_FACTOR, follow_plan

    m, mission = _leg()
    first = mission.timeout_s
    follow_plan(mission, m, [1, 5, 2], 5.0, 40.0, 1.0)  # the same plan: nothing changes
    assert mission.timeout_s == first and mission.rearmed == 0
    follow_plan(mission, m, [1, 7, 8, 2], 50.0, 40.0, 1.0)  # 30 s used, 50 m round the block
    assert mission.timeout_s == 30.0 + LEG_TIMEOUT_BASE_S + LEG_TIMEOUT_FACTOR * 50.0 and mission.rearmed == 1
    follow_plan(mission, m, [1, 9, 2], 1.0, 41.0, 1.0)  # a shorter plan never shortens it
    assert mission.timeout_s == 30.0 + LEG_TIMEOUT_BASE_S + LEG_TIMEOUT_FACTOR * 50.0 and mission.rearmed == 1
    # The leg's event says what the budget became and what it was at first.
    graph = load_building(load_scenario(SCENARIOS_DIR / "demo.toml")).navgraph
    ids = [int(i) for i in graph.node_ids()[:2]]
    mission.waypoints = ids
    close_leg(
        mission, m, graph, arrived=True, timed_out=False, truth_xy=graph.node_xy()[0], t=100.0, distance_m=60.0,
        arrival_radius_m=0.5, rng=np.random.default_rng(0),
    )
    ev = mission.events[-1]
    assert ev["rearmed"] == 1 and ev["budget_s"] == round(mission.timeout_s, 1) and ev["first_budget_s"] == round(first, 1)


def test_a_leg_that_replans_without_end_still_times_out():
    from sim.experiments.waypoints import LEG_TIMEOUT_MAX_FACTOR, follow_plan

    m, mission = _leg()
    for k in range(50):
        follow_plan(mission, m, [1, 100 + k, 2], 200.0, 10.0 + 5.0 * k, 1.0)
    assert mission.timeout_s == LEG_TIMEOUT_MAX_FACTOR * mission.first_timeout_s


def test_a_given_waypoint_timeout_is_not_rearmed():
    from sim.experiments.waypoints import follow_plan

    m, mission = _leg(waypoint_timeout_s=60.0)
    assert mission.timeout_s == 60.0
    follow_plan(mission, m, [1, 7, 8, 2], 500.0, 40.0, 1.0)
    assert mission.timeout_s == 60.0 and mission.rearmed == 0
