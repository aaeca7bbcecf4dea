"""Expectations in scenario files, ``depthnav test`` with JUnit XML, the pytest fixture,
``depthnav config`` and the ``--spawn`` checks."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from sim.cli import main
from sim.experiments.expect import (
    EXPECTATION_FAILED,
    Expectation,
    check,
    failures,
    parse_expectations,
)
from sim.experiments.metric_names import METRICS
from sim.scenario import SCENARIOS_DIR, Scenario, load_scenario
from tests.helpers import err_line

#: A run of a few seconds on the small floor, no figures.
TINY = """
name = "{name}"
seed = 3
[map]
name = "small_floor"
[mission]
max_duration_s = 3.0
[report]
figures = false
[expect]
{expect}
"""


def tiny(tmp_path: Path, name: str, expect: str) -> Path:
    p = tmp_path / f"{name}.toml"
    p.write_text(TINY.format(name=name, expect=expect), encoding="utf-8")
    return p


# --------------------------------------------------------------------------- parsing


@pytest.mark.parametrize(
    ("spec", "op", "value"),
    [(0, "==", 0.0), (2.5, "==", 2.5), ("< 0.10", "<", 0.1), ("<=1", "<=", 1.0), (">  1", ">", 1.0), (">= -2", ">=", -2.0),
     ("!= 0", "!=", 0.0), ("== 1e-3", "==", 0.001), ("0.5", "==", 0.5), (".5", "==", 0.5)],
)
def test_an_expectation_is_a_number_or_a_comparison(spec, op, value) -> None:
    (e,) = parse_expectations({"collisions": spec}, "s.toml")
    assert (e.metric, e.op, e.value) == ("collisions", op, value)


@pytest.mark.parametrize(
    ("table", "pattern"),
    [
        ({"collisons": 0}, r"^s\.toml: key 'expect\.collisons': no such report metric \(did you mean 'collisions'\?\)"),
        ({"collisions": "about 0"}, r"^s\.toml: key 'expect\.collisions' expected a comparison such as"),
        ({"collisions": "< "}, r"key 'expect\.collisions' expected a comparison"),
        ({"collisions": True}, r"key 'expect\.collisions' expected a number or a comparison"),
        ({"collisions": [0]}, r"key 'expect\.collisions' expected a number or a comparison"),
        ({"collisions": float("inf")}, r"key 'expect\.collisions' expected a finite number"),
    ],
)
def test_a_bad_expectation_is_one_line_naming_the_file_and_key(table, pattern) -> None:
    with pytest.raises(InputError, match=pattern) as err:
        parse_expectations(table, "s.toml")
    assert "\n" not in str(err.value)


def test_expect_must_be_a_table() -> None:
    with pytest.raises(InputError, match=r"^s\.toml: key 'expect' expected a table"):
        parse_expectations(3, "s.toml")


_OPS = {"<": float.__lt__, "<=": float.__le__, ">": float.__gt__, ">=": float.__ge__, "==": float.__eq__, "!=": float.__ne__}
_finite = st.floats(allow_nan=False, allow_infinity=False, width=32)


@given(op=st.sampled_from(sorted(_OPS)), value=_finite, actual=_finite)
def test_a_comparison_holds_as_python_compares(op, value, actual) -> None:
    text = f"{op} {value!r}"
    (e,) = parse_expectations({"distance_m": text}, "s.toml")
    assert e.value == value
    assert e.holds(actual) == _OPS[op](float(actual), float(value))
    assert e.holds(int(actual)) == _OPS[op](float(int(actual)), float(value))


@pytest.mark.parametrize("actual", [None, "ok", True, float("nan"), [1]])
def test_a_value_not_measured_does_not_hold(actual) -> None:
    for op in _OPS:
        assert not Expectation("collisions", op, 0.0).holds(actual)


def test_check_reports_each_expectation_and_the_failed_ones() -> None:
    exps = parse_expectations({"collisions": 0, "loc_error_p95_m": "< 0.1", "realtime_factor": "> 1"}, "s.toml")
    block = check(exps, {"collisions": 2, "loc_error_p95_m": 0.05})
    assert block["passed"] is False
    assert [c["held"] for c in block["checks"]] == [False, True, False]
    assert failures(block) == ["collisions = 2 (expected == 0)", "realtime_factor = not measured (expected > 1)"]
    assert check((), {})["passed"] is True


def test_every_documented_metric_has_a_description() -> None:
    assert all(isinstance(v, str) and v for v in METRICS.values())


def test_expect_in_a_scenario_file_and_by_set(tmp_path: Path) -> None:
    p = tiny(tmp_path, "t", 'collisions = 0\nloc_error_p95_m = "< 0.10"')
    scn = load_scenario(p, ["expect.realtime_factor=\"> 1\""])
    assert [str(e) for e in scn.expect] == ["collisions == 0", "loc_error_p95_m < 0.1", "realtime_factor > 1"]
    assert load_scenario(SCENARIOS_DIR / "demo.toml").expect == ()


# --------------------------------------------------------------------------- runs


def test_a_failed_expectation_exits_3_with_it_in_one_line_and_a_met_one_exits_0(tmp_path: Path, capsys) -> None:
    p = tiny(tmp_path, "t", 'collisions = 0\nrealtime_factor = "> 1000000"')
    assert main(["run", str(p), "--out", str(tmp_path / "a")]) == EXPECTATION_FAILED == 3
    out = capsys.readouterr().out
    line = [ln for ln in out.splitlines() if "expectations" in ln]
    assert len(line) == 1 and line[0].startswith("t: expectations: 1 of 2 failed: realtime_factor = ")
    assert "(expected > 1e+06)" in line[0]
    rep = json.loads((tmp_path / "a" / "report.json").read_text())
    assert rep["expect"]["passed"] is False and [c["held"] for c in rep["expect"]["checks"]] == [True, False]
    # The same scenario with the expectation met.
    assert main(["run", str(p), "--out", str(tmp_path / "b"), "--set", 'expect.realtime_factor="> 0"']) == 0
    assert "t: expectations: all 2 held" in capsys.readouterr().out


@pytest.mark.slow
def test_a_sweep_checks_every_trial(tmp_path: Path, capsys) -> None:
    p = tiny(tmp_path, "t", "waypoints_reached = 99")
    rc = main(["sweep", str(p), "--trials", "2", "--workers", "1", "--out", str(tmp_path / "sw")])
    assert rc == 3
    out = capsys.readouterr().out
    assert "t: expectations held on 0 of 2 trials" in out and out.count("waypoints_reached = ") == 2
    rep = json.loads((tmp_path / "sw" / "report.json").read_text())
    assert rep["expect"]["passed"] is False and len(rep["expect"]["trials"]) == 2
    assert rep["expect"]["expectations"] == ["waypoints_reached == 99"]


@pytest.mark.slow
def test_depthnav_test_writes_junit_that_a_junit_reader_reads(tmp_path: Path, capsys) -> None:
    junitparser = pytest.importorskip("junitparser")
    good = tiny(tmp_path, "good", "collisions = 0")
    bad = tiny(tmp_path, "bad", 'distance_m = "> 1000"')
    xml = tmp_path / "ci" / "junit.xml"
    rc = main(["test", str(good), str(bad), "--seeds", "1,2", "--workers", "2", "--junit", str(xml), "--out", str(tmp_path / "runs")])
    assert rc == 3
    out = capsys.readouterr().out
    assert "2 passed, 2 failed, 0 errors" in out
    assert out.count("FAIL  bad seed") == 2 and out.count("PASS  good seed") == 2
    suites = junitparser.JUnitXml.fromfile(str(xml))
    cases = [c for s in suites for c in s]
    assert sorted((c.classname, c.name) for c in cases) == [
        ("depthnav.bad", "seed 1"), ("depthnav.bad", "seed 2"), ("depthnav.good", "seed 1"), ("depthnav.good", "seed 2")]
    for c in cases:
        if c.classname == "depthnav.bad":
            (res,) = c.result
            assert isinstance(res, junitparser.Failure) and res.message.startswith("distance_m = ")
            assert "(expected > 1000)" in res.message
            assert str(tmp_path / "runs" / f"bad-{c.name.replace(' ', '')}" / "report.json") in res.text
        else:
            assert c.is_passed
    assert (tmp_path / "runs" / "good-seed1" / "report.json").is_file()
    # All passing: exit 0.
    assert main(["test", str(good), "--workers", "1", "--out", str(tmp_path / "runs2")]) == 0


def test_depthnav_test_checks_every_file_before_running_any(tmp_path: Path, capsys) -> None:
    good = tiny(tmp_path, "good", "collisions = 0")
    broken = tiny(tmp_path, "broken", "colisions = 0")
    assert main(["test", str(good), str(broken), "--out", str(tmp_path / "runs")]) == 2
    assert err_line(capsys).startswith(f"depthnav: error: {broken}: key 'expect.colisions'")
    assert not (tmp_path / "runs" / "good-seed3").exists()
    assert main(["test", str(good), "--seeds", "1,x"]) == 2
    assert "--seeds '1,x': expected integers >= 0" in err_line(capsys)
    assert main(["test", str(SCENARIOS_DIR / "real_floors.toml")]) == 2
    assert "depthnav test runs mission scenarios" in err_line(capsys)


def test_a_crashed_case_is_an_error_in_junit(tmp_path: Path) -> None:
    from sim.experiments.scenario_tests import ERROR, junit_xml

    junitparser = pytest.importorskip("junitparser")
    res = [{"id": "x-seed0", "scenario": "x", "file": "x.toml", "seed": 0, "report": "r/report.json", "failed": [],
            "outcome": ERROR, "message": "the run stopped at t = 1.00 s on an error: ValueError: boom", "time_s": 1.0}]
    path = tmp_path / "j.xml"
    path.write_text(junit_xml(res))
    (case,) = [c for s in junitparser.JUnitXml.fromfile(str(path)) for c in s]
    (err,) = case.result
    assert isinstance(err, junitparser.Error) and "ValueError: boom" in err.message


# --------------------------------------------------------------------------- pytest fixture

USER_TESTS = """
def test_short_demo(depthnav_scenario):
    run = depthnav_scenario({scenario!r}, seed=3)
    assert run.metrics["distance_m"] > 0.1
    run.assert_expectations()
"""


@pytest.mark.slow
@pytest.mark.parametrize(("expect", "passes"), [("collisions = 0", True), ('distance_m = "> 1000"', False)])
def test_the_pytest_fixture_passes_and_fails_as_the_expectation_says(tmp_path: Path, expect: str, passes: bool) -> None:
    scn = tiny(tmp_path, "user", expect)
    (tmp_path / "test_user.py").write_text(USER_TESTS.format(scenario=str(scn)), encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist", str(tmp_path / "test_user.py")],
                       capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert (r.returncode == 0) == passes, r.stdout[-3000:] + r.stderr[-2000:]
    if not passes:
        assert "AssertionError: user: expectations: 1 of 1 failed: distance_m = " in r.stdout


# --------------------------------------------------------------------------- depthnav config


@pytest.mark.parametrize("name", sorted(p.name for p in SCENARIOS_DIR.glob("*.toml")))
def test_config_prints_the_resolved_scenario_and_it_reads_back_the_same(name: str, capsys) -> None:
    import tomllib

    from sim.config import from_dict
    from sim.experiments.kinds import experiment, load_experiment
    from sim.scenario import with_expectations

    assert main(["config", name]) == 0
    data = tomllib.loads(capsys.readouterr().out)
    exp = experiment(data.pop("kind", "mission"))
    data["base_dir"] = str(SCENARIOS_DIR)  # where the original's relative paths resolve
    again = with_expectations(from_dict, exp.config_type, data, name)
    _, orig = load_experiment(SCENARIOS_DIR / name)
    assert again == orig


def test_config_keeps_expectations_and_overrides(tmp_path: Path, capsys) -> None:
    p = tiny(tmp_path, "t", 'loc_error_p95_m = "< 0.1"')
    assert main(["config", str(p), "--set", "robot.max_speed_mps=0.5"]) == 0
    text = capsys.readouterr().out
    q = tmp_path / "again.toml"
    q.write_text(text)
    scn = load_scenario(q)
    assert scn.robot.max_speed_mps == 0.5 and [str(e) for e in scn.expect] == ["loc_error_p95_m < 0.1"]
    assert scn.kinect == Scenario(name="x").kinect  # the defaults are written out


# --------------------------------------------------------------------------- --spawn


def test_spawn_without_a_display_is_one_line_before_any_work(tmp_path: Path, capsys, monkeypatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    import sim.experiments.runner as runner

    monkeypatch.setattr(runner, "build_run", lambda *a: pytest.fail("the run started"))
    p = tiny(tmp_path, "t", "collisions = 0")
    assert main(["run", str(p), "--out", str(tmp_path / "o"), "--spawn"]) == 2
    assert "--spawn: no display to open the rerun viewer on" in err_line(capsys)


def test_spawn_finds_the_viewer_beside_this_python_without_it_on_path(monkeypatch, tmp_path: Path) -> None:
    from sim.viz import viewer as recording

    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setenv("PATH", str(tmp_path))
    fake_bin = tmp_path / "venv" / "bin"
    fake_bin.mkdir(parents=True)
    (fake_bin / "rerun").write_text("#!/bin/sh\n")
    monkeypatch.setattr(sys, "executable", str(fake_bin / "python"))
    assert recording.viewer_executable() == str(fake_bin / "rerun")
    (fake_bin / "rerun").unlink()
    with pytest.raises(InputError, match=r"^--spawn: the rerun viewer is not installed here"):
        recording.viewer_executable()


def test_the_docs_list_every_metric() -> None:
    doc = (Path(__file__).resolve().parents[2] / "docs" / "scenario_tests.md").read_text(encoding="utf-8")
    section = doc.split("\n## Metrics\n", 1)[1]
    listed = {ln.split("`")[1] for ln in section.splitlines() if ln.startswith("| `")}
    assert listed == set(METRICS)
