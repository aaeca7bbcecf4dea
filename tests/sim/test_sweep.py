"""The sweep engine: local pool, resume after a kill, Ray equals local, the CLI."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from autonomy.common.errors import InputError
from sim.experiments import kinds as experiments
from sim.experiments.sweep import SweepError, read_trials, run_sweep
from tests.helpers import interrupt
from tests.sim import sweep_kind

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def tiny_kind(monkeypatch):
    monkeypatch.setitem(experiments.KINDS, sweep_kind.KIND, sweep_kind.MODULE)


def scenario(tmp_path: Path, **kw) -> Path:
    body = {"name": "tiny", "seed": 5, **kw}
    lines = [f'kind = "{sweep_kind.KIND}"'] + [f"{k} = {json.dumps(v)}" for k, v in body.items()]
    p = tmp_path / "tiny.toml"
    p.write_text("\n".join(lines) + "\n")
    return p


def results(out: Path) -> dict[str, dict]:
    done, skipped = read_trials(out / "trials.jsonl")
    assert not skipped
    return {k: v["result"] for k, v in done.items()}


def test_local_engine_runs_every_trial_once(tmp_path: Path) -> None:
    marks = tmp_path / "marks"
    scn = scenario(tmp_path, marker_dir=str(marks))
    rep = run_sweep(scn, [], tmp_path / "out", trials=6, workers=2, progress=False)
    assert rep["metrics"]["trials"] == 6 and not rep["interrupted"]
    assert rep["sweep"]["engine"] == "local" and rep["sweep"]["run_now"] == 6
    res = results(tmp_path / "out")
    assert sorted(res) == [f"t-{i:04d}" for i in range(6)]
    assert len(list(marks.iterdir())) == 6
    # Same seeds in one process: identical results.
    rep1 = run_sweep(scn, [], tmp_path / "out1", trials=6, workers=1, progress=False)
    assert results(tmp_path / "out1") == res
    assert rep1["metrics"]["mean"] == rep["metrics"]["mean"]
    assert json.loads((tmp_path / "out" / "report.json").read_text())["sweep"]["trials"] == 6
    meta = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert meta["trials"] == 6 and meta["seed"] == 5 and meta["kind"] == sweep_kind.KIND


def test_resume_checks_it_is_the_same_sweep(tmp_path: Path) -> None:
    scn = scenario(tmp_path)
    out = tmp_path / "out"
    run_sweep(scn, [], out, trials=3, workers=1, progress=False)
    with pytest.raises(InputError, match="already holds a sweep"):
        run_sweep(scn, [], out, trials=3, workers=1, progress=False)
    with pytest.raises(InputError, match="different sweep.*trials"):
        run_sweep(scn, [], out, trials=4, workers=1, progress=False, resume=True)
    with pytest.raises(InputError, match="different sweep.*seed"):
        run_sweep(scn, [], out, trials=3, workers=1, progress=False, resume=True, seed=9)
    with pytest.raises(InputError, match="different sweep.*config_hash"):
        run_sweep(scn, ["sleep_s=0.001"], out, trials=3, workers=1, progress=False, resume=True)
    rep = run_sweep(scn, [], out, trials=3, workers=1, progress=False, resume=True)
    assert rep["sweep"]["run_now"] == 0 and rep["sweep"]["resumed"] == 3


def test_a_failing_trial_keeps_the_others(tmp_path: Path) -> None:
    scn = scenario(tmp_path, fail_id="t-0002")
    out = tmp_path / "out"
    with pytest.raises(SweepError, match="t-0002"):
        run_sweep(scn, [], out, trials=4, workers=2, progress=False)
    assert sorted(results(out)) == ["t-0000", "t-0001", "t-0003"]
    assert not (out / "report.json").exists()


def test_kill_part_way_then_resume_loses_nothing_and_runs_nothing_twice(tmp_path: Path) -> None:
    marks = tmp_path / "marks"
    scn = scenario(tmp_path, sleep_s=0.25, marker_dir=str(marks))
    out = tmp_path / "out"
    code = (
        f"import sys; sys.path.insert(0, {str(ROOT)!r})\n"
        "from tests.sim import sweep_kind; sweep_kind.register()\n"
        "from sim.experiments.sweep import run_sweep\n"
        f"run_sweep({str(scn)!r}, [], {str(out)!r}, trials=24, workers=1, progress=False)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, start_new_session=True)
    try:
        deadline = time.time() + 60
        while time.time() < deadline:
            if (out / "trials.jsonl").is_file() and len((out / "trials.jsonl").read_text().splitlines()) >= 4:
                break
            time.sleep(0.05)
        else:
            pytest.fail("the sweep did not get going")
        os.kill(proc.pid, signal.SIGKILL)  # our own child, by its pid
        proc.wait(10)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(10)
    before, _ = read_trials(out / "trials.jsonl")
    assert 4 <= len(before) < 24
    # A half-written last line (as a kill during a write leaves) is dropped on resume.
    with open(out / "trials.jsonl", "a") as f:
        f.write('{"id": "t-0023", "spec": {"id": "t-00')
    rep = run_sweep(scn, [], out, trials=24, workers=2, progress=False, resume=True)
    assert rep["sweep"]["resumed"] == len(before)
    lines = (out / "trials.jsonl").read_text().splitlines()
    ids = [json.loads(line)["id"] for line in lines]
    assert len(ids) == len(set(ids)) == 24
    after, _ = read_trials(out / "trials.jsonl")
    for k, rec in before.items():  # finished trials kept as they were, not re-run
        assert after[k] == rec
        assert len(list(marks.glob(f"{k}.*"))) == 1
    for k in after:
        assert 1 <= len(list(marks.glob(f"{k}.*"))) <= 2  # at most the one cut short by the kill


def test_ctrl_c_keeps_finished_trials_and_says_how_to_resume(tmp_path: Path) -> None:
    marks = tmp_path / "marks"
    scn = scenario(tmp_path, sleep_s=0.6, marker_dir=str(marks))  # ~12 s in all: Ctrl-C lands mid-way even on a loaded machine
    out = tmp_path / "out"
    code = (
        f"import signal, sys; sys.path.insert(0, {str(ROOT)!r})\n"
        # As in a terminal: a job started in the background by a non-interactive shell
        # (as CI may run us) inherits SIGINT ignored, and Python then never raises
        # KeyboardInterrupt.
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "from tests.sim import sweep_kind; sweep_kind.register()\n"
        "from sim.cli import main\n"
        f"sys.exit(main(['sweep', {str(scn)!r}, '--trials', '40', '--workers', '2', '--out', {str(out)!r}]))\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, start_new_session=True, stderr=subprocess.PIPE, text=True)
    jsonl = out / "trials.jsonl"
    # As Ctrl-C, to our own child.
    err = interrupt(proc, signal.SIGINT, lambda: jsonl.is_file() and len(jsonl.read_text().splitlines()) >= 3)
    assert proc.returncode == 130, err
    assert "resume with: depthnav sweep" in err and "--resume" in err
    rep = json.loads((out / "report.json").read_text())
    assert rep["interrupted"] is True
    done, _ = read_trials(out / "trials.jsonl")
    assert rep["metrics"]["trials_done"] == len(done) >= 3
    n_marks = len(list(marks.iterdir()))
    time.sleep(1.5)
    assert len(list(marks.iterdir())) == n_marks  # the workers are gone
    rep = run_sweep(scn, [], out, trials=40, workers=2, progress=False, resume=True)
    assert rep["sweep"]["resumed"] == len(done) and rep["metrics"]["trials"] == 40


def test_cli_sweep_one_line_errors(tmp_path: Path, capsys) -> None:
    from sim.cli import main

    scn = scenario(tmp_path)
    assert main(["sweep", str(scn), "--trials", "0", "--out", str(tmp_path / "o")]) == 2
    assert "--trials" in capsys.readouterr().err
    assert main(["sweep", str(scn), "--trials", "2", "--workers", "1", "--out", str(tmp_path / "o"), "--address", "x:1"]) == 2
    assert main(["sweep", str(tmp_path / "missing.toml")]) == 2
    assert main(["sweep", str(scn), "--trials", "2", "--workers", "1", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr()
    assert "report.json" in out.out
    err = main(["sweep", str(scn), "--trials", "3", "--workers", "1", "--out", str(tmp_path / "o"), "--resume"])
    assert err == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_ray_missing_is_a_one_line_input_error(tmp_path: Path, monkeypatch) -> None:
    import builtins

    real = builtins.__import__

    def fake(name, *a, **k):
        if name == "ray":
            raise ImportError("no ray")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", fake)
    with pytest.raises(InputError, match=r"pip install 'depthnav\[ray\]'"):
        run_sweep(scenario(tmp_path), [], tmp_path / "o", trials=2, engine="ray", workers=1, progress=False)


@pytest.mark.slow
def test_ray_engine_equals_local_engine(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    scn = scenario(tmp_path)
    run_sweep(scn, [], tmp_path / "local", trials=8, workers=2, progress=False)
    rep = run_sweep(scn, [], tmp_path / "ray", trials=8, engine="ray", workers=2, progress=False)
    assert rep["sweep"]["engine"] == "ray"
    assert results(tmp_path / "ray") == results(tmp_path / "local")


@pytest.mark.slow
def test_mission_kind_is_sweepable(tmp_path: Path) -> None:
    scn = tmp_path / "m.toml"
    scn.write_text(
        'name = "tiny_mission"\nseed = 3\n[map]\nname = "small_floor"\n'
        "[mission]\nfollower = \"ground_truth\"\nn_random_waypoints = 1\nmax_duration_s = 2.0\n"
        "[localization]\nenabled = false\n[report]\nfigures = false\nprogress = false\n"
    )
    rep = run_sweep(scn, [], tmp_path / "out", trials=2, workers=2, progress=False)
    assert rep["kind"] == "mission" and rep["trials"] == 2
    res = results(tmp_path / "out")
    assert sorted(res) == ["trial-0000", "trial-0001"]
    assert all(r["metrics"]["frames"] > 0 for r in res.values())
    # One trial of the sweep, recorded: `depthnav run --seed <its seed> --rrd` is the same run.
    from sim.cli import main
    from tests.helpers import rrd_chunks

    one = res["trial-0001"]
    rrd = tmp_path / "one" / "trial.rrd"
    assert main(["run", str(scn), "--out", str(tmp_path / "one"), "--seed", str(one["seed"]), "--rrd", str(rrd)]) == 0
    again = json.loads((tmp_path / "one" / "report.json").read_text())["metrics"]
    for k in ("frames", "distance_m", "collisions", "waypoints_reached"):
        assert again[k] == one["metrics"][k], k
    assert any(p == "/world/robot" for p, _ in rrd_chunks(rrd))


def test_no_cluster_at_the_address_fails_before_the_kinds_preparation(tmp_path: Path, monkeypatch) -> None:
    """A sweep connects to Ray before any long preparation (a kind's recorded drive), so
    a cluster that is not there is a one-line error at once."""
    pytest.importorskip("ray")

    def prepare(*_a, **_k):
        raise AssertionError("prepared before connecting")

    monkeypatch.setattr("sim.experiments.sweep._prepare", prepare)
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    with pytest.raises(InputError, match="--address auto: cannot connect to a Ray cluster"):
        run_sweep(scenario(tmp_path), [], tmp_path / "o", trials=2, engine="ray", workers=1, address="auto", progress=False)
