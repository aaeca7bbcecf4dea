"""Every program that drives the robot stack from sim/ or bench/ reads it only through
:class:`autonomy.stack.StackOutput`: of :class:`autonomy.stack.RobotStack` it touches
nothing but the commands in ``COMMANDS``.

Two checks: the source (an AST scan of attribute accesses on the stack, however it is
held), and the running code (a stack that notes every attribute its caller touches,
driven a second of simulated time by the runner, the env, the relocalization trials and
the drive recorder).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import numpy as np
import pytest

from autonomy.stack import RobotStack
from tests.helpers import GL

ROOT = Path(__file__).resolve().parents[1]

#: What a caller may do with the stack: step it, and the commands that change it.
COMMANDS = frozenset({"step", "reset", "set_goal", "redecide", "relocalize", "prepare_recovery"})

#: Names the stack is held under everywhere (``stack.x``, ``run.stack.x``, ``self._stack.x``).
STACK_NAMES = frozenset({"stack", "_stack"})


def _makes_a_stack(call: ast.expr) -> bool:
    f = call.func if isinstance(call, ast.Call) else None
    return (isinstance(f, ast.Name) and f.id == "RobotStack") or (isinstance(f, ast.Attribute) and f.attr == "RobotStack")


def _stack_names(tree: ast.AST) -> set[str]:
    """The names a module holds a stack under: the usual ones, those assigned a new
    ``RobotStack(...)`` and the parameters annotated ``RobotStack``."""
    names = set(STACK_NAMES)
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and _makes_a_stack(node.value):
            for t in node.targets:
                if isinstance(t, ast.Name):
                    names.add(t.id)
                elif isinstance(t, ast.Attribute):
                    names.add(t.attr)
        elif isinstance(node, ast.arg) and node.annotation is not None and "RobotStack" in ast.unparse(node.annotation):
            names.add(node.arg)
    return names


def stack_reads(source: str, where: str) -> list[str]:
    """Every attribute of a stack the source touches other than ``COMMANDS``, as
    ``where:line: expression``."""
    tree = ast.parse(source)
    names = _stack_names(tree)
    bad = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        v = node.value
        holder = v.id if isinstance(v, ast.Name) else v.attr if isinstance(v, ast.Attribute) else None
        if holder in names and node.attr not in COMMANDS:
            bad.append((node.lineno, node.col_offset, f"{where}:{node.lineno}: {ast.unparse(node)}"))
    return [line for *_, line in sorted(bad)]


def test_sim_and_bench_read_the_stack_only_through_its_output() -> None:
    bad = []
    for folder in ("sim", "bench"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            bad += stack_reads(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))
    assert not bad, "\n".join(bad)


def test_the_scan_sees_reads_however_the_stack_is_held() -> None:
    src = """
def f(run, s: RobotStack, self):
    run.stack.step(d, None, 0.0)
    x = run.stack.pose
    self._stack.reset(None)
    y = self._stack.localizer.particles
    z = s.navigator
    sensing = RobotStack(vm, None)
    sensing.perceive(d)
    np.stack([a, b])
"""
    found = [line.split(": ", 1)[1] for line in stack_reads(src, "f")]
    assert found == ["run.stack.pose", "self._stack.localizer", "s.navigator", "sensing.perceive"]


# ------------------------------------------------------------------ the running code


class WatchedStack:
    """A :class:`RobotStack` that notes the name of every attribute its caller gets or
    sets (the stack's own methods work on the real one, unwatched)."""

    touched: set[str] = set()

    def __init__(self, *args, **kwargs) -> None:
        object.__setattr__(self, "_real", RobotStack(*args, **kwargs))

    def __getattr__(self, name: str):
        WatchedStack.touched.add(name)
        return getattr(self._real, name)

    def __setattr__(self, name: str, value) -> None:
        WatchedStack.touched.add(name)
        setattr(self._real, name, value)


@pytest.fixture
def watched(monkeypatch: pytest.MonkeyPatch) -> set[str]:
    """Every RobotStack sim/ makes from now on is a :class:`WatchedStack`; yields the
    names touched."""
    import autonomy.stack
    import sim.envs.depthnav
    import sim.experiments.loc_replay
    import sim.experiments.reloc_sample
    import sim.experiments.site  # noqa: F401

    monkeypatch.setattr(autonomy.stack, "RobotStack", WatchedStack)
    for name, mod in list(sys.modules.items()):
        if name.startswith("sim.") and getattr(mod, "RobotStack", None) is RobotStack:
            monkeypatch.setattr(mod, "RobotStack", WatchedStack)
    WatchedStack.touched = set()
    return WatchedStack.touched


def _only_commands(touched: set[str]) -> None:
    assert touched, "the watched stack was not used"
    assert touched <= COMMANDS, f"read from the stack: {sorted(touched - COMMANDS)}"


@pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")
def test_the_runner_reads_only_the_output(tmp_path: Path, watched: set[str]) -> None:
    from sim.experiments.runner import run_scenario
    from sim.scenario import SCENARIOS_DIR, load_scenario

    scn = load_scenario(
        SCENARIOS_DIR / "demo.toml",
        ["map.name=\"small_floor\"", "mission.max_duration_s=1.0", "actors.random_people=1", "report.trace_s=[0.0, 1.0]",
         "report.rrd_every=10", "faults.events=[{kind = \"kidnap\", at_s = 0.5}]", "localization.truth_reset_after_s=0.0"],
    )
    rep = run_scenario(scn, tmp_path, seed=1, rrd=tmp_path / "run.rrd", progress=False)
    assert rep["metrics"]["frames"] == 30 and rep["recovery"]["faults"]
    _only_commands(watched)


@pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")
def test_the_env_reads_only_the_output(tmp_path: Path, watched: set[str]) -> None:
    from sim.envs.depthnav import DepthNavEnv, EnvConfig

    env = DepthNavEnv(EnvConfig(stack_policy=True, observe_points=16, observe_pose_estimate=True, rrd=str(tmp_path / "env.rrd"), rrd_every=2),
                      render_mode="rgb_array")
    try:
        _, info = env.reset(seed=1)
        for _ in range(5):
            _, _, _, _, info = env.step(info["stack_action"])
        env.render()
    finally:
        env.close()
    _only_commands(watched)


def test_the_relocalization_trials_read_only_the_output(watched: set[str]) -> None:
    from sim.experiments.reloc_sample import sample

    assert len(sample("small_floor", None, 1, seed=0, seconds=1.0)) == 1
    _only_commands(watched)


@pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")
def test_the_drive_recorder_reads_only_the_output(tmp_path: Path, watched: set[str]) -> None:
    from sim.experiments.drives import RecordingConfig, record_log

    record_log(RecordingConfig(map="small_floor", route=((3.9, 5.1), (3.9, 6.95)), max_duration_s=1.0), tmp_path / "d.log.npz")
    with np.load(tmp_path / "d.log.npz") as z:
        assert len(z["t"]) > 1
    _only_commands(watched)
