"""The package layers: lower layers never import higher ones (docs/architecture.md).

autonomy/ is what runs on the robot (no mujoco, sim or rerun); sim/simulator/ is the
simulated site; sim/envs/ and sim/experiments/ use it (the env never the experiments);
only sim/viz/ imports rerun, and it draws what the experiments hand it without
importing them; the CLI sits on top of everything.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: autonomy/'s sub-packages from the bottom up: each may import only those before it,
#: except that localization and navigation, side by side, never import each other, and
#: planes (the mapping experiments' plane extraction) sits beside them on perception.
AUTONOMY_LAYERS = ("common", "maps", "perception", "localization", "navigation", "planes", "stack")
_SIDE_BY_SIDE = {"localization": ("navigation",), "navigation": ("localization",), "planes": ("localization", "navigation")}


def _autonomy_forbidden() -> dict[str, tuple[str, ...]]:
    out = {}
    for i, layer in enumerate(AUTONOMY_LAYERS[:-1]):
        above = AUTONOMY_LAYERS[i + 1 :]
        out[f"autonomy/{layer}"] = tuple(f"autonomy.{a}" for a in (*above, *_SIDE_BY_SIDE.get(layer, ())))
    return out


#: Package folder -> module prefixes none of its files may import.
FORBIDDEN = {
    **_autonomy_forbidden(),
    "autonomy": ("sim", "mujoco", "rerun"),
    "sim/simulator": ("sim.envs", "sim.experiments", "sim.viz", "sim.cli", "sim.scenario", "rerun"),
    "sim/envs": ("sim.experiments", "sim.cli", "rerun"),
    "sim/experiments": ("sim.cli", "rerun"),
    "sim/viz": ("sim.experiments", "sim.envs", "sim.rl", "sim.cli"),
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
    mods = imported_modules(ROOT / "sim" / "experiments" / "site.py")
    assert "autonomy.stack" in mods and "sim.simulator.step" in mods


def test_every_module_of_autonomy_is_in_a_layer() -> None:
    """A module left at the package's top (or a new sub-package) has no layer rule."""
    top = {p.stem for p in (ROOT / "autonomy").glob("*.py")} - {"__init__"}
    subs = {p.name for p in (ROOT / "autonomy").iterdir() if (p / "__init__.py").exists()}
    assert not top and subs == set(AUTONOMY_LAYERS)


#: Packages without import circles.
CIRCLE_FREE = ("autonomy", "sim", "bench")


def import_circle(folder: str, root: Path = ROOT) -> list[str] | None:
    """An import circle among the modules under ``folder`` (of the tree at ``root``), or
    None (imports at any depth in a file count: a function-local import closes a circle
    as surely)."""
    modules = {}
    for path in (root / folder).rglob("*.py"):
        rel = path.relative_to(root).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        modules[name] = path
    graph = {m: {i for i in imported_modules(p) if i in modules and i != m} for m, p in modules.items()}
    # A package's __init__ re-exporting its modules is not a circle through them.
    graph = {m: {i for i in deps if not m.startswith(i + ".")} for m, deps in graph.items()}
    done: set[str] = set()

    def visit(m: str, stack: list[str]) -> list[str] | None:
        if m in stack:
            return [*stack[stack.index(m) :], m]
        if m in done:
            return None
        for n in sorted(graph[m]):
            found = visit(n, [*stack, m])
            if found:
                return found
        done.add(m)
        return None

    for m in sorted(graph):
        circle = visit(m, [])
        if circle is not None:
            return circle
    return None


@pytest.mark.parametrize("folder", CIRCLE_FREE)
def test_no_import_circle(folder: str) -> None:
    """No module of the folder imports, through others, itself."""
    circle = import_circle(folder)
    assert circle is None, " -> ".join(circle)


def test_a_function_local_import_closes_a_circle(tmp_path: Path) -> None:
    """The check itself: two modules importing each other, one of them only inside a
    function (as an import put off to hide the circle would), are a circle."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "low.py").write_text("def f():\n    from pkg.high import g\n\n    return g\n")
    (pkg / "high.py").write_text("from pkg import low\n\n\ndef g():\n    return low\n")
    assert import_circle("pkg", tmp_path) in (["pkg.high", "pkg.low", "pkg.high"], ["pkg.low", "pkg.high", "pkg.low"])
    (pkg / "low.py").write_text("def f():\n    return 1\n")
    assert import_circle("pkg", tmp_path) is None
