"""A long run's mission: when it ends, and when it goes on past its distance."""

from __future__ import annotations

import numpy as np

from sim.experiments.runner import load_building
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
