"""Map hygiene: each check on a hand-made map with a known answer, the one-line messages,
the logger, and properties of the cleaning."""

from __future__ import annotations

import logging
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.maps.map_hygiene import (
    LOGGER_NAME,
    MAX_LISTED,
    _overlap_pairs,
    _overlapping,
    clean_segments,
)
from autonomy.maps.vectormap import (
    MapFormatError,
    VectorMap,
    check_vectormap,
    format_vectormap_json,
    format_vectormap_text,
    load_vectormap,
    load_vectormap_checked,
    parse_vectormap_json,
    parse_vectormap_text,
)

ROOT = Path(__file__).resolve().parents[2]
WALLS = "0, 0, 10, 0\n10, 0, 10, 8\n10, 8, 0, 8\n0, 8, 0, 0\n"  # a 10 x 8 m room, lines 1-4


def _text(rows) -> str:
    return "".join(f"{a!r}, {b!r}, {c!r}, {d!r}\n" for a, b, c, d in np.asarray(rows, float).tolist())


def _messages(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == LOGGER_NAME]


def _one_line(msg: str, source: str) -> None:
    assert msg.startswith(source), msg
    assert "\n" not in msg, msg


# --------------------------------------------------------------------------- zero length


def test_zero_length_dropped_and_logged_once(caplog):
    text = WALLS + "3, 3, 3, 3\n# note\n1, 2, 1.0000000000001, 2\n4, 4, 5, 5\n"
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        vm = parse_vectormap_text(text, "z.vectormap.txt")
    assert vm.n_segments == 5
    assert _messages(caplog) == ["z.vectormap.txt: dropped 2 zero-length segment(s) at line(s) 5, 7"]
    # Only an exactly zero length is dropped without the checks (a VectorMap needs no more).
    assert parse_vectormap_text(text, "z.vectormap.txt", checks=False).n_segments == 6


def test_zero_length_listing_stops_after_ten(caplog):
    text = WALLS + "2, 2, 2, 2\n" * 12
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        parse_vectormap_text(text, "z.txt")
    (msg,) = _messages(caplog)
    assert msg == "z.txt: dropped 12 zero-length segment(s) at line(s) 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, ..."
    assert MAX_LISTED == 10


def test_all_zero_length_is_an_error():
    with pytest.raises(MapFormatError) as ei:
        parse_vectormap_text("1, 1, 1, 1\n2, 2, 2, 2\n", "d.txt")
    assert str(ei.value) == "d.txt: no wall segments left after dropping zero-length ones"


# --------------------------------------------------------------------------- duplicates


def test_duplicates_dropped_keeping_the_first(caplog):
    text = WALLS + "10, 0, 0, 0\n0, 0, 10, 0\n10, 8.0000000000001, 10, 0\n2, 2, 3, 3\n2, 2, 3, 3.000001\n"
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        vm = parse_vectormap_text(text, "dup.txt")
    # lines 5 (reversed 1), 6 (= 1) and 7 (reversed 2, within 1e-9 m) go; 8 and 9 differ by 1 um.
    np.testing.assert_array_equal(vm.segments[:4], np.loadtxt(WALLS.splitlines(), delimiter=","))
    assert vm.n_segments == 6
    msgs = _messages(caplog)
    assert msgs[0] == (
        "dup.txt: dropped 3 duplicate segment(s) at line(s) 5 = 1, 6 = 1, 7 = 2 "
        "(the end points of the earlier one, in either direction; kept the earlier)"
    )
    # 1 um apart is no duplicate, but it is the same wall twice: an overlap.
    assert len(msgs) == 2 and "at line(s) 8 & 9" in msgs[1]


def test_duplicate_names_json_elements_and_lines(caplog):
    vm = VectorMap([[0, 0, 4, 0], [0, 0, 0, 3], [4, 0, 0, 0]])
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        back = parse_vectormap_json(format_vectormap_json(vm), "d.json")
    assert back.n_segments == 2
    assert _messages(caplog) == [
        "d.json: dropped 1 duplicate segment(s) at element(s) [2] (line 4) = [0] (line 2) "
        "(the end points of the earlier one, in either direction; kept the earlier)"
    ]


# --------------------------------------------------------------------------- overlaps

# Each case: two segments and whether they are an overlap.
_OVERLAP_CASES = {
    "collinear, overlapping 1 m": ([0, 0, 3, 0], [2, 0, 5, 0], True),
    "reversed, overlapping": ([0, 0, 3, 0], [5, 0, 2, 0], True),
    "one inside the other": ([0, 0, 10, 0], [4, 0, 6, 0], True),
    "5 mm apart across, overlapping": ([0, 0, 3, 0], [1, 0.005, 4, 0.005], True),
    "0.2 degrees apart, overlapping": ([0, 0, 3, 0], [1, 0, 1 + 2 * math.cos(0.0035), 2 * math.sin(0.0035)], True),
    "0.3 degrees apart, 1.04 cm off at the end": ([0, 0, 3, 0], [1, 0, 1 + 2 * math.cos(0.0052), 2 * math.sin(0.0052)], False),
    "diagonal, overlapping": ([1, 1, 4, 4], [3, 3, 6, 6], True),
    "across the 0/180 degree wrap": ([0, 0, 3, 0.005], [4, 0.004, 1, -0.003], True),
    "touching end to end": ([0, 0, 0.4, 0], [0.4, 0, 0.8, 0], False),
    "overlapping by 5 mm only": ([0, 0, 1, 0], [0.995, 0, 2, 0], False),
    "collinear with a gap": ([0, 0, 1, 0], [1.5, 0, 2, 0], False),
    "parallel 2 cm apart": ([0, 0, 3, 0], [1, 0.02, 4, 0.02], False),
    "1 degree apart": ([0, 0, 3, 0], [0, 0, 3 * math.cos(0.0175), 3 * math.sin(0.0175)], False),
    "crossing": ([0, 0, 2, 2], [0, 2, 2, 0], False),
    "end to end at right angles": ([0, 0, 2, 0], [2, 0, 2, 2], False),
}


@pytest.mark.parametrize("name", sorted(_OVERLAP_CASES))
def test_overlap_pair(name):
    a, b, expect = _OVERLAP_CASES[name]
    seg = np.array([a, b], float)
    assert bool(_overlapping(seg, np.array([0]), np.array([1]))[0]) == expect
    assert bool(_overlapping(seg, np.array([1]), np.array([0]))[0]) == expect  # symmetric
    assert (_overlap_pairs(seg).tolist() == [[0, 1]]) == expect
    # Far from the origin the answer is the same.
    far = seg + [3000.0, -2000.0, 3000.0, -2000.0]
    assert (_overlap_pairs(far).tolist() == [[0, 1]]) == expect


def test_overlaps_reported_not_modified(caplog):
    text = WALLS + "2, 0, 5, 0\n10, 7, 10, 9\n4, 8, 6, 8\n"  # lines 5-7 overlap lines 1, 2, 3
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        vm = parse_vectormap_text(text, "o.txt")
    assert vm.n_segments == 7
    assert _messages(caplog) == [
        "o.txt: 3 pair(s) of overlapping collinear segments at line(s) 1 & 5, 2 & 6, 3 & 7 "
        "(kept as they are; merge each pair into one wall)"
    ]
    (f,) = _findings_of(text)
    assert f.check == "overlap" and f.severity == "warning"
    assert f.pairs.tolist() == [[0, 4], [1, 5], [2, 6]]
    assert f.rows.tolist() == [0, 1, 2, 4, 5, 6]


def _findings_of(text: str):
    return clean_segments(np.loadtxt(text.splitlines(), delimiter=",").reshape(-1, 4), "o.txt").findings


def test_split_walls_touching_end_to_end_are_not_overlaps():
    """Walls split into collinear 0.4 m pieces (as the building generator writes them)."""
    rng = np.random.default_rng(2)
    rows = []
    for k in range(40):
        a = rng.uniform(-50, 50, 2)
        ang = rng.choice([0.0, math.pi / 2, rng.uniform(0, math.pi)])
        n = int(rng.integers(2, 60))
        pts = a + np.linspace(0, 0.4 * n, n + 1)[:, None] * [math.cos(ang), math.sin(ang)]
        rows.append(np.concatenate([pts[:-1], pts[1:]], axis=1))
        if k % 2:  # the other face of the wall, 0.1 m away
            off = 0.1 * np.array([-math.sin(ang), math.cos(ang)])
            rows.append(np.concatenate([pts[:-1] + off, pts[1:] + off], axis=1))
    seg = np.concatenate(rows)
    assert _overlap_pairs(seg).shape == (0, 2)
    assert clean_segments(seg, "split").findings == ()


def test_the_large_generated_building_has_no_findings():
    from sim.simulator import blueprints

    vm = blueprints.generate_building(blueprints.BuildingConfig.large(), 0).vectormap
    assert vm.n_segments > 10000
    assert check_vectormap(vm) == []


@pytest.mark.parametrize("name", ["small_floor", "corridor_loop"])
def test_shipped_maps_load_without_findings(name):
    _, findings = load_vectormap_checked(ROOT / "sim" / "assets" / f"{name}.vectormap.txt")
    assert findings == []


def _near_collinear_map(rng: np.random.Generator, n: int) -> np.ndarray:
    base = rng.uniform(-40, 40, (4, 2))
    ang = rng.choice([0.0, math.pi / 2, 1e-3, math.pi - 1e-3, rng.uniform(0, math.pi)], 4)
    k = rng.integers(0, 4, n)
    d = np.stack([np.cos(ang[k]), np.sin(ang[k])], 1)
    normal = np.stack([-d[:, 1], d[:, 0]], 1)
    turn = ang[k] + rng.normal(0, math.radians(0.3), n)
    p0 = base[k] + d * rng.uniform(-5, 5, n)[:, None] + normal * rng.normal(0, 0.008, n)[:, None]
    p1 = p0 + np.stack([np.cos(turn), np.sin(turn)], 1) * (rng.exponential(2, n) + 0.01)[:, None]
    seg = np.concatenate([p0, p1], 1)
    flip = rng.random(n) < 0.5
    seg[flip] = seg[flip][:, [2, 3, 0, 1]]
    return seg


@pytest.mark.parametrize("seed", range(20))
def test_overlap_search_finds_every_pair_the_exact_test_accepts(seed):
    """The binned search against testing all N^2 pairs, on lines crowded with near-collinear pieces."""
    rng = np.random.default_rng(seed)
    seg = _near_collinear_map(rng, int(rng.integers(2, 120)))
    i, j = np.triu_indices(seg.shape[0], 1)
    ok = _overlapping(seg, i, j)
    assert _overlap_pairs(seg).tolist() == np.stack([i[ok], j[ok]], 1).tolist()


# --------------------------------------------------------------------------- units / extent


def test_millimetre_map_is_a_one_line_error_suggesting_the_scale(tmp_path):
    p = tmp_path / "floor.unscaled.vectormap.txt"
    p.write_text(_text([[0, 0, 10000, 0], [10000, 0, 10000, 8000], [0, 0, 0, 8000]]))
    with pytest.raises(MapFormatError) as ei:
        load_vectormap(p)
    msg = str(ei.value)
    _one_line(msg, str(p))
    assert "map extent 10000.0 x 8000.0 m is over 5000 m: looks like millimetres; scale by 0.001" in msg
    assert "(x from 0 at line 1 to 10000.0 at line 1)" in msg
    assert ei.value.source == str(p)
    vm = load_vectormap(p, scale=0.001)
    assert vm.extent() == (0.0, 0.0, 10.0, 8.0)


def test_a_stray_coordinate_names_its_line():
    text = WALLS + "0, 0, 1e9, 0\n"
    with pytest.raises(MapFormatError) as ei:
        parse_vectormap_text(text, "s.txt")
    msg = str(ei.value)
    _one_line(msg, "s.txt")
    assert "not a building in metres (a stray coordinate?)" in msg and "at line 5)" in msg


def test_large_map_is_a_warning(caplog):
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        vm = parse_vectormap_text("0, 0, 800, 0\n0, 0, 0, 30\n", "big.txt")
    assert vm.n_segments == 2
    assert _messages(caplog) == [
        "big.txt: map extent 800.0 x 30.0 m is over 500 m, large for one building: check the units "
        "(centimetres need scale 0.01, millimetres 0.001) (x from 0 at line 1 to 800.0 at line 1)"
    ]


def test_tiny_map_is_an_error():
    with pytest.raises(MapFormatError) as ei:
        parse_vectormap_json('[\n{"p0": {"x": 0, "y": 0}, "p1": {"x": 0.01, "y": 0}},\n'
                             '{"p0": {"x": 0, "y": 0}, "p1": {"x": 0, "y": 0.008}}\n]', "km.json")
    msg = str(ei.value)
    _one_line(msg, "km.json")
    assert "map extent 0.01 x 0.008 m is under 0.5 m" in msg and "kilometres? scale by 1000" in msg
    assert "at element [0] (line 2)" in msg


def test_scaled():
    vm = VectorMap([[0, 0, 1000, 0], [0, 0, 0, 2500]], name="mm")
    s = vm.scaled(0.001)
    np.testing.assert_allclose(s.segments, [[0, 0, 1, 0], [0, 0, 0, 2.5]])
    assert s.name == "mm" and vm.segments[0, 2] == 1000
    for bad in (0, -1, math.nan, math.inf, True, "0.001"):
        with pytest.raises(InputError, match="scale: expected a positive number"):
            vm.scaled(bad)
    with pytest.raises(InputError, match="scale"):
        parse_vectormap_text(WALLS, scale=-1.0)


# --------------------------------------------------------------------------- non-finite


@pytest.mark.parametrize(
    "text, prefix, needle",
    [
        (WALLS + "1, 2, nan, 4\n", "n.txt:5: ", "expected a finite number for x2, got 'nan'"),
        (WALLS + "1 2 3 inf\n", "n.txt:5: ", "expected a finite number for y2, got 'inf'"),
        (WALLS + "\n-Infinity, 2, 3, 4\n", "n.txt:6: ", "expected a finite number for x1"),
        (WALLS + "1, 2, 3, 1e999\n", "n.txt:5: ", "expected finite numbers"),
    ],
)
def test_non_finite_text_is_a_one_line_error(text, prefix, needle):
    with pytest.raises(MapFormatError) as ei:
        parse_vectormap_text(text, "n.txt")
    msg = str(ei.value)
    _one_line(msg, "n.txt")
    assert msg.startswith(prefix) and needle in msg, msg
    assert ei.value.line == int(prefix.split(":")[1])


_SEG = '{"p0": {"x": 0, "y": 0}, "p1": {"x": 4, "y": 3}}'


@pytest.mark.parametrize(
    "bad, prefix",
    [
        ('{"p0": {"x": NaN, "y": 0}, "p1": {"x": 1, "y": 1}}', "n.json:3: [1].p0.x: "),
        ('{"p0": {"x": 0, "y": 0}, "p1": {"x": 1, "y": Infinity}}', "n.json:3: [1].p1.y: "),
        ('{"p0": {"x": 0, "y": -Infinity}, "p1": {"x": 1, "y": 1}}', "n.json:3: [1].p0.y: "),
        ('{"p0": {"x": 0, "y": 0}, "p1": {"x": 1e999, "y": 1}}', "n.json:3: [1].p1.x: "),
        ('{"p0": {"x": 0, "y": 0}, "p1": {"x": 1, "y": ' + "9" * 400 + "}}", "n.json:3: [1].p1.y: "),
    ],
)
def test_non_finite_json_is_a_one_line_error_with_line_and_path(bad, prefix):
    with pytest.raises(MapFormatError) as ei:
        parse_vectormap_json("[\n" + _SEG + ",\n" + bad + "\n]\n", "n.json")
    msg = str(ei.value)
    _one_line(msg, "n.json")
    assert msg.startswith(prefix) and "expected a finite number" in msg, msg
    assert ei.value.line == 3


def test_clean_segments_reports_non_finite_rows_itself():
    (f,) = clean_segments([[0, 0, 1, 1], [0, np.nan, 1, 1]], "m.txt", labels=[7, 9], unit="line(s)").findings
    assert f.check == "non_finite" and f.severity == "error" and f.line == 9
    assert f.message == "m.txt: 1 segment(s) with a NaN or infinite coordinate at line(s) 9"


# --------------------------------------------------------------------------- API and logging


def test_check_vectormap_on_a_map_in_memory():
    vm = VectorMap([[0, 0, 10, 0], [0, 0, 0, 8], [10, 0, 0, 0], [2, 0, 6, 0]], name="mem")
    findings = check_vectormap(vm)
    assert [f.check for f in findings] == ["duplicate", "overlap"]
    assert findings[0].message.startswith("mem: would drop 1 duplicate segment(s) at segment(s) [2] = [0] ")
    assert findings[1].message.startswith("mem: 1 pair(s) of overlapping collinear segments at segment(s) [0] & [3] ")
    assert vm.n_segments == 4
    assert check_vectormap(VectorMap([[0, 0, 10, 0], [0, 0, 0, 8]])) == []
    (f,) = check_vectormap(VectorMap([[0, 0, 9000, 0]]), source="floor.txt")
    assert f.severity == "error" and str(f).startswith("floor.txt: map extent 9000.0 x 0 m")


def test_load_vectormap_checked_returns_instead_of_logging(tmp_path, caplog):
    p = tmp_path / "f.vectormap.txt"
    p.write_text(WALLS + "1, 1, 1, 1\n")
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        vm, findings = load_vectormap_checked(p)
    assert vm.n_segments == 4 and vm.name == "f"
    assert [f.message for f in findings] == [f"{p}: dropped 1 zero-length segment(s) at line(s) 5"]
    assert _messages(caplog) == []


def test_warnings_are_logged_before_an_error(caplog):
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME), pytest.raises(MapFormatError, match="millimetres"):
        parse_vectormap_text(_text([[0, 0, 9000, 0], [5, 5, 5, 5]]), "e.txt")
    assert _messages(caplog) == ["e.txt: dropped 1 zero-length segment(s) at line(s) 2"]


def test_without_logging_configured_a_finding_prints_as_one_line():
    code = (
        "from autonomy.maps.vectormap import parse_vectormap_text\n"
        "parse_vectormap_text('0, 0, 4, 0\\n1, 1, 1, 1\\n0, 0, 0, 3\\n', 'z.txt')\n"
        "import logging; logging.getLogger('depthnav.map').setLevel(logging.ERROR)\n"
        "parse_vectormap_text('0, 0, 4, 0\\n2, 2, 2, 2\\n', 'quiet.txt')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert r.stderr == "z.txt: dropped 1 zero-length segment(s) at line(s) 2\n"
    assert r.stdout == ""


# --------------------------------------------------------------------------- properties

_coord = st.sampled_from([0.0, 1.0, 2.5, -3.0, 1.0 + 2e-10, 7.25])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(_coord, _coord, _coord, _coord), min_size=1, max_size=30))
def test_cleaning_drops_only_degenerate_and_repeated_segments_and_is_idempotent(rows):
    seg = np.array(rows, dtype=np.float64).reshape(-1, 4)
    res = clean_segments(seg, "p.txt")
    # Reference, one row at a time: a row goes if its rounded end points coincide or an
    # earlier kept row has the same rounded end points in either order.
    q = np.round(seg / 1e-9) * 1e-9
    expect, seen = [], set()
    for i, (a, b, c, d) in enumerate(q.tolist()):
        key = min((a, b, c, d), (c, d, a, b))
        if (a, b) == (c, d) or key in seen:
            continue
        seen.add(key)
        expect.append(i)
    assert res.kept.tolist() == expect
    np.testing.assert_array_equal(res.segments, seg[expect])
    n_zero = int((q[:, :2] == q[:, 2:]).all(axis=1).sum())
    dropped = {f.check for f in res.findings if f.check in ("zero_length", "duplicate")}
    assert ("zero_length" in dropped) == (n_zero > 0)
    assert ("duplicate" in dropped) == (len(expect) + n_zero < len(rows))
    for f in res.findings:
        _one_line(f.message, "p.txt")
    if expect:
        again = clean_segments(res.segments, "p.txt")
        np.testing.assert_array_equal(again.segments, res.segments)
        assert [f.check for f in again.findings] == [f.check for f in res.findings if f.check not in dropped]


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 60))
def test_overlap_report_ignores_row_order_and_direction(seed, n):
    rng = np.random.default_rng(seed)
    seg = _near_collinear_map(rng, n)
    pairs = {tuple(p) for p in _overlap_pairs(seg).tolist()}
    perm = rng.permutation(n)
    shuffled = seg[perm]
    flip = rng.random(n) < 0.5
    shuffled[flip] = shuffled[flip][:, [2, 3, 0, 1]]
    back = {tuple(sorted((int(perm[i]), int(perm[j])))) for i, j in _overlap_pairs(shuffled).tolist()}
    assert back == pairs


def test_text_and_json_report_the_same_findings(caplog):
    seg = [[0, 0, 10, 0], [0, 0, 0, 8], [10, 0, 0, 0], [2, 0, 6, 0], [3, 3, 3, 3]]
    vm_rows = np.array(seg, float)
    text = _text(vm_rows)
    json_text = format_vectormap_json(VectorMap(vm_rows[:4])).replace(
        "\n]", ',\n{"p0": {"x": 3.0, "y": 3.0}, "p1": {"x": 3.0, "y": 3.0}}\n]'
    )
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        a = parse_vectormap_text(text, "t.txt")
        b = parse_vectormap_json(json_text, "t.json")
    np.testing.assert_array_equal(a.segments, b.segments)
    msgs = _messages(caplog)
    assert [m.split(":")[0] for m in msgs] == ["t.txt"] * 3 + ["t.json"] * 3
    assert format_vectormap_text(a) == format_vectormap_text(b)
