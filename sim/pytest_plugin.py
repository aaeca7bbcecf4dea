"""The pytest plugin installed with depthnav (entry point ``pytest11``): the
``depthnav_scenario`` fixture runs a scenario in the test's temporary directory and
returns its :class:`sim.testing.ScenarioRun`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

from sim.testing import ScenarioRun, run_scenario_file


@pytest.fixture
def depthnav_scenario(tmp_path: Path) -> Callable[..., ScenarioRun]:
    """``depthnav_scenario(scenario, seed=None, set=(), figures=False)``: run a mission
    scenario headless (each call in its own directory under the test's ``tmp_path``)
    and return the run; ``run.assert_expectations()`` fails the test on any failed
    ``[expect]`` entry."""
    calls = [0]

    def run(scenario: str | Path, seed: int | None = None, set: Sequence[str] = (), figures: bool = False) -> ScenarioRun:
        calls[0] += 1
        return run_scenario_file(scenario, tmp_path / f"run{calls[0]}", seed=seed, set=set, figures=figures)

    return run
