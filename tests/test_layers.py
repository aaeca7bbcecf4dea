"""The package layers: lower layers never import higher ones (docs/architecture.md).

autonomy/ is what runs on the robot (no mujoco, sim or rerun); sim/simulator/ is the
simulated site; sim/envs/ and sim/experiments/ use it (the env never the experiments);
only sim/viz/ imports rerun; the CLI sits on top of everything.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Package folder -> module prefixes none of its files may import.
FORBIDDEN = {
    "autonomy": ("sim", "mujoco", "rerun"),
    "sim/simulator": ("sim.envs", "sim.experiments", "sim.viz", "sim.cli", "sim.scenario", "rerun"),
    "sim/envs": ("sim.experiments", "sim.cli", "rerun"),
    "sim/experiments": ("sim.cli", "rerun"),
    "sim/scenes": ("sim.envs", "sim.experiments", "sim.cli", "rerun"),
}


def imported_modules(path: Path) -> set[str]:
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


@pytest.mark.parametrize("folder", sorted(FORBIDDEN))
def test_lower_layers_do_not_import_higher_ones(folder: str) -> None:
    bad = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for mod in imported_modules(path):
            for prefix in FORBIDDEN[folder]:
                if mod == prefix or mod.startswith(prefix + "."):
                    bad.append(f"{path.relative_to(ROOT)} imports {mod}")
    assert not bad, "\n".join(sorted(set(bad)))


def test_the_layer_check_sees_imports() -> None:
    """The check itself: it finds the imports a file does make."""
    mods = imported_modules(ROOT / "sim" / "experiments" / "runner.py")
    assert "autonomy.stack" in mods and "sim.simulator.step" in mods
