"""The localization comparison (BV2012, VI-A): config, trials, and a short 10 x 4 run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from autonomy.common.errors import InputError
from sim.experiments.kinds import load_experiment
from sim.experiments.loc_compare import PAPER, trials

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "localization_comparison.toml"


def test_scenario_parses_with_the_papers_settings() -> None:
    exp, cfg = load_experiment(SCENARIO)
    assert exp.kind == "localization_comparison"
    assert cfg.replays == 100 and cfg.failure_error_m == 1.0
    assert cfg.approaches == ("fspf", "kr", "ks", "kc")
    assert cfg.odometry.translation_noise == 0.2 and cfg.odometry.rotation_noise == 0.2
    assert cfg.scans.n_beams == 514 and cfg.scans.ks_samples == cfg.fspf.n_max == 2000
    assert len(cfg.recording.furniture) >= 5 and len(cfg.recording.people) >= 5
    with pytest.raises(InputError, match="approach"):
        load_experiment(SCENARIO, ['approaches=["fspf", "laser"]'])
    with pytest.raises(InputError, match="recording.nope"):
        load_experiment(SCENARIO, ["recording.nope=1"])


def test_trials_are_replays_per_approach_with_shared_seeds() -> None:
    _, cfg = load_experiment(SCENARIO)
    specs = trials(cfg, 3, 7)
    assert len(specs) == 12 and len({s["id"] for s in specs}) == 12
    by = {(s["approach"], s["replay"]): s["seed"] for s in specs}
    for i in range(3):
        assert len({by[(a, i)] for a in cfg.approaches}) == 1  # common random numbers
    assert len({by[("fspf", i)] for i in range(3)}) == 3
    assert trials(cfg, 3, 7) == specs


@pytest.mark.slow
def test_short_comparison_10_replays_x_4_approaches(tmp_path: Path) -> None:
    from sim.experiments.sweep import run_sweep

    sets = [
        f"cache_dir={tmp_path / 'cache'}",
        "recording.max_duration_s=8.0",
        "trace_hz=2.0",
    ]
    out = tmp_path / "out"
    rep = run_sweep(SCENARIO, sets, out, trials=10, workers=2, progress=False)
    assert not rep["interrupted"]
    assert rep["log"]["frames"] >= 200 and rep["log"]["duration_s"] <= 8.1
    appr = rep["approaches"]
    assert list(appr) == ["fspf", "kr", "ks", "kc"]
    for a, r in appr.items():
        assert r["trials"] == 10
        for k in ("failure_rate", "cpu_load", "mean_error_m", "median_error_m"):
            assert np.isfinite(r[k]) and r[k] >= 0, (a, k)
        assert r["paper"] == PAPER[a]
    # FSPF holds on in the corridor; the whole cloud costs the most, one row the least.
    assert appr["fspf"]["failure_rate"] <= 0.1
    assert appr["fspf"]["mean_error_m"] < 0.5
    assert appr["kc"]["cpu_load"] > appr["ks"]["cpu_load"] and appr["kc"]["cpu_load"] > appr["kr"]["cpu_load"]
    for f in ("fig5_traces.png", "fig6_failure_rate.png", "fig7_error_cdf.png", "report.json", "trials.jsonl", "sweep.json"):
        assert (out / f).stat().st_size > 0, f
    on_disk = json.loads((out / "report.json").read_text())
    assert on_disk["approaches"]["kr"]["trials"] == 10 and on_disk["sweep"]["trials"] == 40
    # The log is cached: a second sweep of the same scenario records nothing.
    logs = sorted((tmp_path / "cache").glob("*.log.npz"))
    assert len(logs) == 1
    mtime = logs[0].stat().st_mtime
    rep2 = run_sweep(SCENARIO, [*sets, 'approaches=["kr"]'], tmp_path / "out2", trials=2, workers=1, progress=False)
    assert logs[0].stat().st_mtime == mtime
    # Same seeds, same replays (timing aside).
    a = {json.loads(x)["id"]: json.loads(x)["result"] for x in (out / "trials.jsonl").read_text().splitlines()}
    b = {json.loads(x)["id"]: json.loads(x)["result"] for x in (tmp_path / "out2" / "trials.jsonl").read_text().splitlines()}
    for k in b:
        a[k].pop("timing")
        b[k].pop("timing")
        assert a[k] == b[k]
    assert rep2["approaches"]["kr"]["trials"] == 2
