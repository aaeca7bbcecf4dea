"""``depthnav test``: mission scenarios as CI tests, one test case per scenario and seed.

Every scenario is loaded (and so checked) before any runs; the cases then run headless on
a process pool (:func:`sim.experiments.sweep_engines.pool_map`), each writing its report
and figures to its own directory. A case passes when its run ends and every expectation
of its ``[expect]`` table holds (:mod:`sim.experiments.expect`), fails when one does not,
and is an error when the run crashed. :func:`junit_xml` writes the outcome in the JUnit
XML that GitHub Actions, GitLab and Jenkins read.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import socket
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from pathlib import Path

from autonomy.common.errors import InputError
from sim.experiments.expect import failures

#: Outcomes of a case.
PASSED, FAILED, ERROR, NOT_RUN = "passed", "failed", "error", "not run"


def plan_cases(scenarios: Sequence[str], seeds: Sequence[int] | None, overrides: Sequence[str], out_root: Path) -> list[dict]:
    """One case spec per (scenario, seed), every scenario loaded now so that a bad file
    or key is a one-line error before anything runs. ``seeds`` None: each scenario's own."""
    from sim.experiments.kinds import load_experiment, shipped_scenario

    cases: list[dict] = []
    used: set[str] = set()
    for given in scenarios:
        exp, scn = load_experiment(given, list(overrides))
        if exp.kind != "mission":
            raise InputError(
                f"{given}: a {exp.kind!r} experiment; depthnav test runs mission scenarios "
                "(a sweep checks [expect] on every trial: depthnav sweep)"
            )
        for seed in (seeds if seeds else [scn.seed]):
            if seed < 0:
                raise InputError(f"--seeds: expected integers >= 0, got {seed}")
            case_id = f"{scn.name}-seed{seed}"
            k = 2
            while case_id in used:  # two files with one name: keep both directories
                case_id, k = f"{scn.name}-{k}-seed{seed}", k + 1
            used.add(case_id)
            cases.append({
                "id": case_id, "scenario": scn.name, "file": str(shipped_scenario(Path(given))), "seed": int(seed),
                "overrides": list(overrides), "out": str(out_root / case_id),
            })
    return cases


def run_case(spec: dict) -> dict:
    """Run one case (in whatever process this is); its outcome."""
    from sim.experiments.kinds import RunCrashed
    from sim.experiments.runner import run_scenario
    from sim.scenario import load_scenario

    t0 = time.perf_counter()
    scn = load_scenario(spec["file"], spec["overrides"])
    scn = dataclasses.replace(scn, report=dataclasses.replace(scn.report, progress=False))
    out = Path(spec["out"])
    outcome = {"id": spec["id"], "scenario": spec["scenario"], "file": spec["file"], "seed": spec["seed"],
               "report": str(out / "report.json"), "failed": [], "message": ""}
    try:
        report = run_scenario(scn, out, seed=spec["seed"], progress=False)
    except (RunCrashed, InputError) as exc:
        outcome.update(outcome=ERROR, message=str(exc))
    else:
        block = report.get("expect", {"passed": True, "checks": []})
        outcome["failed"] = failures(block)
        outcome["checks"] = len(block["checks"])
        outcome["metrics"] = report["metrics"]
        if report["interrupted"]:
            outcome.update(outcome=ERROR, message="the run was interrupted")
        else:
            outcome["outcome"] = PASSED if block["passed"] else FAILED
            outcome["message"] = "; ".join(outcome["failed"])
    outcome["time_s"] = round(time.perf_counter() - t0, 3)
    return outcome


def run_cases(specs: list[dict], workers: int, on_result: Callable[[dict], None]) -> tuple[list[dict], bool]:
    """Run the cases on ``workers`` processes; (outcomes in the specs' order, whether
    Ctrl-C stopped it). A case that did not run (stopped first) is ``not run``."""
    from sim.experiments.sweep_engines import pool_map

    done: dict[str, dict] = {}

    def on_done(res: dict) -> None:
        done[res["id"]] = res
        on_result(res)

    def on_error(spec: dict, exc: BaseException) -> None:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else ""
        res = {"id": spec["id"], "scenario": spec["scenario"], "file": spec["file"], "seed": spec["seed"],
               "report": str(Path(spec["out"]) / "report.json"), "failed": [], "outcome": ERROR,
               "message": f"{type(exc).__name__}: {msg}", "time_s": 0.0}
        on_done(res)

    interrupted = False
    try:
        pool_map(run_case, specs, workers, on_done, on_error)
    except KeyboardInterrupt:
        interrupted = True
    out = []
    for s in specs:
        out.append(done.get(s["id"]) or {"id": s["id"], "scenario": s["scenario"], "file": s["file"], "seed": s["seed"],
                                          "report": "", "failed": [], "outcome": NOT_RUN, "message": "interrupted before it ran",
                                          "time_s": 0.0})
    return out, interrupted


def outcome_line(res: dict) -> str:
    """One line per finished case for the terminal."""
    word = {PASSED: "PASS", FAILED: "FAIL", ERROR: "ERROR", NOT_RUN: "NOT RUN"}[res["outcome"]]
    line = f"{word:<5} {res['scenario']} seed {res['seed']} ({res['time_s']:.0f} s)"
    if res["outcome"] == PASSED:
        n = res.get("checks", 0)
        return f"{line}: {n} expectation{'s' if n != 1 else ''} held" if n else f"{line}: ran to the end (no expectations)"
    return f"{line}: {res['message']}" + (f" ({res['report']})" if res["report"] else "")


def junit_xml(results: list[dict], suite: str = "depthnav", wall_s: float = 0.0) -> str:
    """JUnit XML of the outcomes: one ``testsuite``, one ``testcase`` per scenario and
    seed (classname the scenario, name its seed), a ``failure`` per failed expectation
    set, an ``error`` per crash, ``skipped`` for a case Ctrl-C stopped before it ran; the
    report's path in ``system-out``."""
    count = {k: sum(r["outcome"] == k for r in results) for k in (PASSED, FAILED, ERROR, NOT_RUN)}
    root = ET.Element("testsuites", name=suite, tests=str(len(results)), failures=str(count[FAILED]),
                      errors=str(count[ERROR]), skipped=str(count[NOT_RUN]), time=f"{wall_s:.3f}")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(results)), failures=str(count[FAILED]),
                       errors=str(count[ERROR]), skipped=str(count[NOT_RUN]), time=f"{wall_s:.3f}",
                       timestamp=dt.datetime.now().isoformat(timespec="seconds"), hostname=socket.gethostname())
    for r in results:
        tc = ET.SubElement(ts, "testcase", classname=f"{suite}.{r['scenario']}", name=f"seed {r['seed']}",
                           file=r["file"], time=f"{r['time_s']:.3f}")
        if r["outcome"] == FAILED:
            el = ET.SubElement(tc, "failure", message=r["message"], type="expectation")
            el.text = "\n".join(r["failed"]) + f"\nreport: {r['report']}"
        elif r["outcome"] == ERROR:
            el = ET.SubElement(tc, "error", message=r["message"].splitlines()[0] if r["message"] else "", type="run")
            el.text = r["message"] + (f"\nreport: {r['report']}" if r["report"] else "")
        elif r["outcome"] == NOT_RUN:
            ET.SubElement(tc, "skipped", message=r["message"])
        if r["report"]:
            ET.SubElement(tc, "system-out").text = f"report: {r['report']}"
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
