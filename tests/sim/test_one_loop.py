"""One closed loop: a scenario run and the gym env, on the same seed, command the same velocities.

Both go through the one simulator step (``SimStep``) and the one robot stack
(``RobotStack``) with the same random streams (``EpisodeSeeds``); the env's
``stack_policy`` exposes the stack's command, and stepping the env with it must retrace
the scenario run frame by frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sim  # noqa: F401  (registers DepthNav-v0)
from sim.envs.depthnav import DepthNavEnv
from sim.experiments.runner import run_scenario
from sim.experiments.site import load_building
from sim.experiments.waypoints import plan_mission
from sim.scenario import SCENARIOS_DIR, load_scenario
from sim.simulator.step import EpisodeSeeds, SimStep

OVERRIDES = [
    'map.name="small_floor"',
    "actors.random_furniture=0",
    "actors.random_people=1",
    "mission.waypoints=[24]",
    "mission.start_node=22",
    "mission.target_distance_m=0",
    "mission.max_duration_s=3.0",
    "report.figures=false",
]
SEED = 5


def _runner_commands(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[np.ndarray, np.ndarray]:
    """The velocity the runner sent to the simulator each frame, and the true poses."""
    sent: list[np.ndarray] = []
    poses: list[np.ndarray] = []
    real = SimStep.step

    def spy(self, velocity):
        sent.append(np.array(velocity, dtype=np.float64))
        frame = real(self, velocity)
        poses.append(frame.pose.copy())
        return frame

    monkeypatch.setattr(SimStep, "step", spy)
    scn = load_scenario(SCENARIOS_DIR / "demo.toml", OVERRIDES)
    run_scenario(scn, tmp_path, seed=SEED, progress=False)
    monkeypatch.undo()
    return np.array(sent), np.array(poses)


def _env_commands(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The stack's command the env reports each step, stepping with it as the action."""
    scn = load_scenario(SCENARIOS_DIR / "demo.toml", OVERRIDES)
    building = load_building(scn)
    mission = plan_mission(scn.mission, building.navgraph, EpisodeSeeds.from_seed(SEED).mission)
    goal = building.navgraph.node_xy()[building.navgraph.index_of(mission.goal)]
    env = DepthNavEnv(
        scenario=SCENARIOS_DIR / "demo.toml", overrides=OVERRIDES, depth_shape=(480, 640), stack_policy=True,
        terminate_on_success=False, terminate_on_collision=False, max_steps=10_000,
    )
    try:
        _, info = env.reset(seed=SEED, options={"start_pose": mission.start_pose, "goal": goal})
        sent, poses = [], []
        for _ in range(n):
            sent.append(info["stack_command"].copy())
            _, _, _, _, info = env.step(info["stack_action"])
            poses.append(info["pose"].copy())
    finally:
        env.close()
    return np.array(sent), np.array(poses)


@pytest.mark.slow
def test_runner_and_env_command_the_same_velocities(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    runner_cmd, runner_pose = _runner_commands(tmp_path, monkeypatch)
    assert len(runner_cmd) == 90 and np.abs(runner_cmd).max() > 0.1  # it drove
    env_cmd, env_pose = _env_commands(len(runner_cmd))
    np.testing.assert_allclose(env_cmd, runner_cmd, rtol=0, atol=1e-9)
    np.testing.assert_allclose(env_pose, runner_pose, rtol=0, atol=1e-9)
