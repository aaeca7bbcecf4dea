"""Scenario runs for a user's own test suite (pytest or any other).

:func:`run_scenario_file` runs one scenario headless and returns a :class:`ScenarioRun`:
its report, metrics and the outcome of its ``[expect]`` table. With pytest the
``depthnav_scenario`` fixture (:mod:`sim.pytest_plugin`, installed with the package)
runs it in the test's temporary directory::

    def test_demo_reaches_every_waypoint(depthnav_scenario):
        run = depthnav_scenario("demo.toml", seed=3, set=["mission.max_duration_s=60"])
        run.assert_expectations()
        assert run.metrics["waypoints_failed"] == 0
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sim.experiments.expect import failures, summary_line


@dataclass(frozen=True)
class ScenarioRun:
    """A finished run: where it wrote, its report, and its expectations' outcome."""

    name: str
    seed: int
    out_dir: Path
    report: dict[str, Any]

    @property
    def metrics(self) -> dict[str, Any]:
        """The report's metrics (:data:`sim.experiments.metric_names.METRICS`)."""
        return self.report["metrics"]

    @property
    def passed(self) -> bool:
        """Every expectation held (True when there are none) and the run was not interrupted."""
        return bool(self.report.get("expect", {}).get("passed", True)) and not self.report["interrupted"]

    @property
    def failures(self) -> list[str]:
        """The failed expectations, one ``metric = actual (expected ...)`` each."""
        return failures(self.report.get("expect", {}))

    def assert_expectations(self) -> None:
        """Raise AssertionError naming every failed expectation and the report."""
        if self.report["interrupted"]:
            raise AssertionError(f"{self.name}: the run was interrupted ({self.out_dir / 'report.json'})")
        if not self.passed:
            raise AssertionError(summary_line(self.name, self.report["expect"]) + f" ({self.out_dir / 'report.json'})")


def run_scenario_file(
    scenario: str | Path, out_dir: str | Path, *, seed: int | None = None, set: Sequence[str] = (), figures: bool = False,
) -> ScenarioRun:
    """Run a mission scenario (a file, or the name of one of the project's) headless into
    ``out_dir``; ``set`` holds ``--set``-style overrides. A crash raises
    :class:`sim.experiments.kinds.RunCrashed`, a bad file or key :class:`InputError`."""
    from autonomy.common.errors import InputError
    from sim.experiments.kinds import load_experiment
    from sim.experiments.runner import run_scenario

    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise InputError(f"seed: expected an integer >= 0, got {seed!r}")
    exp, scn = load_experiment(scenario, list(set))
    if exp.kind != "mission":
        raise InputError(f"{scenario}: a {exp.kind!r} experiment, not a mission scenario")
    scn = dataclasses.replace(scn, report=dataclasses.replace(scn.report, progress=False, figures=figures))
    report = run_scenario(scn, out_dir, seed=seed, progress=False)
    return ScenarioRun(scn.name, int(report["seed"]), Path(out_dir), report)
