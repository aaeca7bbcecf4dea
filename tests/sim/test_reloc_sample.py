"""Relocalization from unknown starts on the map alone (sim/experiments/reloc_sample.py)
and its command, ``depthnav reloc-sample``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from sim.cli import main
from sim.experiments.reloc_sample import parse_region, sample

finite = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False)


@given(finite, finite, st.floats(min_value=1e-3, max_value=1e3), st.floats(min_value=1e-3, max_value=1e3))
def test_a_region_reads_back_as_its_box(x0: float, y0: float, w: float, h: float) -> None:
    box = (x0, y0, x0 + w, y0 + h)
    if not (box[2] > box[0] and box[3] > box[1]):
        return  # w or h lost to rounding at this magnitude
    assert parse_region(",".join(repr(v) for v in box)) == box


@pytest.mark.parametrize("text", ["1,2,3", "a,b,c,d", "1,2,1,3", "0,5,1,4", "0,0,inf,1", ""])
def test_a_bad_region_is_one_line_naming_the_option(text: str) -> None:
    with pytest.raises(InputError, match="^--region: expected"):
        parse_region(text)


def test_the_command_reports_bad_input_in_one_line(capsys) -> None:
    assert main(["reloc-sample", "--region", "1,2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("depthnav: error: --region")
    assert main(["reloc-sample", "--region", "100,100,101,101", "--n", "1"]) == 2
    assert "no free place" in capsys.readouterr().err
    assert main(["reloc-sample", "--n", "0"]) == 2
    assert "--n: expected at least 1" in capsys.readouterr().err
    assert main(["reloc-sample", "--map", "small_floor", "--n", "1", "--seconds", "0.1", "--furniture", "100"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [err[0]] and err[0].startswith("depthnav: error: --furniture: only ") and "actors." not in err[0], err
    for opt, value in (("--seconds", "inf"), ("--seconds", "-2"), ("--noise-m", "-1"), ("--noise-m", "nan"), ("--furniture", "-1"), ("--furniture", "101"),
                       ("--odometry-noise", "-0.1"), ("--odometry-noise", "1"), ("--odometry-noise", "nan")):
        assert main(["reloc-sample", "--n", "1", opt, value]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"depthnav: error: {opt}: expected"), err


@pytest.mark.slow
def test_a_corridor_start_by_an_office_door_is_found_where_it_is() -> None:
    """Two unknown starts in a short stretch of corridor by an office door (its
    surroundings repeat nowhere else): each is found within 40 s, within 15 cm."""
    trials = sample("corridor_loop", (37.8, 33.1, 38.8, 33.6), 2, seed=3, seconds=40.0)
    assert len(trials) == 2
    for tr in trials:
        assert 37.8 <= tr.start[0] <= 38.8 and 33.1 <= tr.start[1] <= 33.6 and -math.pi <= tr.start[2] <= math.pi
        assert tr.relocalized, tr
        assert tr.seconds < 40.0 and tr.error_m < 0.15 and tr.heading_error_deg < 3.0, tr
    # Seeded: the same places again.
    again = sample("corridor_loop", (37.8, 33.1, 38.8, 33.6), 1, seed=3, seconds=0.1)
    assert np.allclose(again[0].start, trials[0].start) and not again[0].relocalized


def test_furniture_stands_in_the_open_areas_and_no_start_lies_on_a_piece() -> None:
    """``--furniture``: the pieces stand where the scenarios put random furniture (the map's
    open areas), drawn from their own stream, and every start clears every piece by the
    robot's radius."""
    from sim.simulator.blueprints import load_blueprint
    from sim.simulator.building import Building, random_furniture

    region = (26.0, 9.0, 34.0, 16.0)
    furnished = sample("corridor_loop", region, 6, seed=4, seconds=0.1, furniture=8)
    bp = load_blueprint("corridor_loop")
    pieces = random_furniture(Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms)), 8, np.random.default_rng([4, 1]), 0.3)
    for tr in furnished:
        for f in pieces:
            assert math.hypot(tr.start[0] - f.x, tr.start[1] - f.y) > 0.5 * math.hypot(*f.dims[:2]) + 0.3
    assert all(region[0] <= tr.start[0] <= region[2] and region[1] <= tr.start[1] <= region[3] for tr in furnished)
    with pytest.raises(InputError, match="^--furniture: "):
        sample("corridor_loop", region, 1, seed=4, seconds=0.1, furniture=101)
