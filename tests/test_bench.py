"""The benchmark harness (`make bench`) runs and writes its results file: smoke tests of
one quick group and of bench/noise_bench.py (the numbers themselves are measured by
`make bench`, never asserted)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _bench_group(group: str, out: Path) -> tuple[subprocess.CompletedProcess, dict]:
    """``bench/run.py --quick --only GROUP``: the finished process and the results it wrote."""
    p = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "run.py"), "--quick", "--only", group, "--out", str(out)],
        capture_output=True, text=True, timeout=600, cwd=ROOT,
    )
    assert p.returncode == 0, p.stderr
    return p, json.loads(out.read_text())


def test_bench_harness_writes_results(tmp_path: Path) -> None:
    p, res = _bench_group("maps", tmp_path / "results.json")
    assert {"map_load_9000", "world_compile_9000", "map_graph_9000"} <= set(res)
    assert res["map_graph_9000"]["coverage"] >= 0.95 and res["map_graph_9000"]["min_clearance_m"] >= 0.35
    for row in res.values():
        assert {"median_ms", "min_ms", "max_ms", "target_ms", "paper_ms"} <= set(row)
        assert row["min_ms"] <= row["median_ms"] <= row["max_ms"]
    assert "benchmark" in p.stdout and "map_load_9000" in p.stdout


def test_every_group_is_registered() -> None:
    sys.path.insert(0, str(ROOT / "bench"))
    import run

    assert list(run._groups()) == run.GROUP_NAMES


def test_the_open3d_group_is_optional(tmp_path: Path) -> None:
    """Without open3d the group says it is skipped and writes nothing; with it, its rows."""
    p, res = _bench_group("open3d", tmp_path / "results.json")
    try:
        import open3d  # noqa: F401
    except ImportError:
        assert res == {} and "Open3D comparison is skipped" in p.stderr
    else:
        assert res["o3d_plane_frame"]["fspf_speedup"] > 0 and res["o3d_plane_ransac"]["ransac_speedup"] > 0


def test_the_noise_benchmark_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """bench/noise_bench.py times the noise model alone, for 1 and 2 threads."""
    sys.path.insert(0, str(ROOT / "bench"))
    import noise_bench

    assert noise_bench.benchmark_noise(repeats=2) > 0
    assert noise_bench.main(["--repeats", "2"]) == 0
    assert capsys.readouterr().out.count("ms median") == 2
