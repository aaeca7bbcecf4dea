"""Vector map and navigation graph: formats, round trips, error messages, speed."""

from __future__ import annotations

import json
import logging
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.maps.navgraph import (
    NavEdge,
    NavGraph,
    NavNode,
    format_navgraph_json,
    load_navgraph,
    parse_navgraph_json,
    save_navgraph,
)
from autonomy.maps.vectormap import (
    MapFormatError,
    VectorMap,
    format_vectormap_json,
    format_vectormap_text,
    load_vectormap,
    parse_vectormap_json,
    parse_vectormap_text,
    save_vectormap,
)


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def _random_map(n: int, seed: int = 0, extremes: bool = True) -> VectorMap:
    rng = np.random.default_rng(seed)
    seg = rng.uniform(-60.0, 60.0, (n, 4))
    seg[: n // 3] = np.round(seg[: n // 3], 2)  # some short decimals as real files have
    if extremes:  # they survive the formats (the loader's extent check would refuse them)
        seg[0] = [1e-300, -0.0, 123456789.123, 5e-324]
    return VectorMap(seg, name="rand")


# --------------------------------------------------------------------------- VectorMap


def test_vectormap_basic_properties():
    vm = VectorMap.from_segments([[0, 0, 3, 4], [1, 1, 1, -1]], name="t")
    assert vm.n_segments == 2
    assert vm.segments.dtype == np.float64 and vm.segments.flags.c_contiguous
    assert not vm.segments.flags.writeable
    np.testing.assert_allclose(vm.lengths, [5.0, 2.0])
    assert vm.total_length_m == pytest.approx(7.0)
    assert vm.extent() == (0.0, -1.0, 3.0, 4.0)
    # left normal of p0->p1: (0,0)->(3,4) has left normal (-4, 3)/5
    np.testing.assert_allclose(vm.normals, [[-0.8, 0.6], [1.0, 0.0]])
    np.testing.assert_allclose(np.hypot(*vm.normals.T), 1.0)


def test_vectormap_copies_input():
    a = np.array([[0.0, 0.0, 1.0, 0.0]])
    vm = VectorMap(a)
    a[0, 0] = 9.0
    assert vm.segments[0, 0] == 0.0
    with pytest.raises(ValueError):
        vm.segments[0, 0] = 1.0


@pytest.mark.parametrize(
    "bad, needle",
    [
        ([[0, 0, 1]], "shape"),
        ([[[0, 0, 1, 1]]], "shape"),
        ([[0, 0, 1, np.nan]], "not finite"),
        ([[0, 0, np.inf, 1]], "not finite"),
        ([[1, 1, 1, 1]], "zero length"),
        ([["a", 0, 1, 1]], "not numeric"),
    ],
)
def test_vectormap_from_segments_validation(bad, needle):
    with pytest.raises(InputError, match=needle):
        VectorMap.from_segments(bad)


# --------------------------------------------------------------------------- round trips


def test_text_json_round_trip_exact():
    vm = _random_map(500)
    t = parse_vectormap_text(format_vectormap_text(vm), checks=False)
    j = parse_vectormap_json(format_vectormap_json(vm), checks=False)
    assert np.array_equal(_bits(t.segments), _bits(vm.segments))
    assert np.array_equal(_bits(j.segments), _bits(vm.segments))
    # text -> json -> text
    t2 = parse_vectormap_text(
        format_vectormap_text(parse_vectormap_json(format_vectormap_json(t), checks=False)), checks=False
    )
    assert np.array_equal(_bits(t2.segments), _bits(vm.segments))


@pytest.mark.parametrize("fname", ["a.vectormap.txt", "b_vector.txt", "c.txt", "d.vectormap.json", "e.JSON"])
def test_save_load_by_suffix(tmp_path, fname):
    vm = _random_map(50, seed=1)
    p = save_vectormap(vm, tmp_path / fname)
    back = load_vectormap(p, checks=False)
    assert np.array_equal(_bits(back.segments), _bits(vm.segments))
    assert back.name == fname.split(".")[0].removesuffix("_vector")
    text = p.read_text()
    if fname.lower().endswith(".json"):
        assert isinstance(json.loads(text), list)
    else:
        assert text.splitlines()[1].count(",") == 3


def test_text_format_variants():
    text = (
        "# a comment\n"
        "\n"
        "0, 0, 1, 0\r\n"
        "   1,2,3,4   \n"
        "1 2\t3    5\n"
        "  # indented comment\n"
        "+1.5e1 , -.5 , 2. , 0\n"
    )
    vm = parse_vectormap_text(text)
    np.testing.assert_array_equal(
        vm.segments, [[0, 0, 1, 0], [1, 2, 3, 4], [1, 2, 3, 5], [15, -0.5, 2, 0]]
    )
    assert parse_vectormap_text("\ufeff0,0,1,1").n_segments == 1


# --------------------------------------------------------------------------- hypothesis

_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
_comma_sep = st.sampled_from([",", ", ", " ,", " , ", ",\t", "  ,   "])
_space_sep = st.sampled_from([" ", "\t", "   ", " \t "])
_fmt = st.sampled_from([repr, lambda v: format(v, ".17g"), lambda v: format(v, ".16e")])


@st.composite
def _text_map(draw):
    rows = draw(
        st.lists(st.tuples(_finite, _finite, _finite, _finite), min_size=1, max_size=20).filter(
            lambda rs: any(r[0] != r[2] or r[1] != r[3] for r in rs)
        )
    )
    rows = [r for r in rows if r[0] != r[2] or r[1] != r[3]]
    lines = []
    for r in rows:
        if draw(st.booleans()):
            lines.append(draw(st.sampled_from(["", "# note", "   ", "#1,2,3,4"])))
        seps = draw(st.lists(_comma_sep if draw(st.booleans()) else _space_sep, min_size=3, max_size=3))
        f = draw(_fmt)
        lead, trail = draw(st.sampled_from(["", " ", "\t"])), draw(st.sampled_from(["", " ", "\r"]))
        lines.append(lead + f(r[0]) + seps[0] + f(r[1]) + seps[1] + f(r[2]) + seps[2] + f(r[3]) + trail)
    return rows, "\n".join(lines) + draw(st.sampled_from(["", "\n", "\n\n"]))


@settings(max_examples=200, deadline=None)
@given(_text_map())
def test_text_parser_exact_property(case):
    rows, text = case
    vm = parse_vectormap_text(text, "h.vectormap.txt", checks=False)
    assert np.array_equal(_bits(vm.segments), _bits(np.array(rows, dtype=np.float64)))


_garbage_tokens = st.sampled_from(
    ["1", "-2.5", "1e3", "1e999", "nan", "inf", "-inf", "x", "1_0", "٣", ",", " ", "\t", "#",
     "\n", "\r", "..", "+", "e5", "0x10", "\x00", "1,2,3,4", "\u2003", "\ufeff"]
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(st.text(max_size=200), st.lists(_garbage_tokens, max_size=60).map("".join)))
def test_text_parser_garbage_never_crashes(text):
    try:
        vm = parse_vectormap_text(text, "g.txt")
    except MapFormatError as e:
        assert str(e).startswith("g.txt")
        assert "\n" not in str(e)
    else:
        assert vm.n_segments >= 1 and np.isfinite(vm.segments).all()


_json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda ch: st.lists(ch, max_size=4) | st.dictionaries(st.sampled_from(["p0", "p1", "x", "y", "z"]), ch, max_size=4),
    max_leaves=20,
)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.text(max_size=100), _json_values.map(json.dumps)))
def test_json_parsers_garbage_never_crash(text):
    for parse in (parse_vectormap_json, parse_navgraph_json):
        try:
            parse(text, "g.json")
        except MapFormatError as e:
            assert str(e).startswith("g.json") and "\n" not in str(e)


# --------------------------------------------------------------------------- text errors


@pytest.mark.parametrize(
    "text, line, needle",
    [
        ("0,0,1,1\n1,2,3\n", 2, 'expected 4 numbers "x1, y1, x2, y2", got 3 fields'),
        ("0,0,1,1\n\n# c\n1,2,3,4,5\n", 4, "got 5 fields"),
        ("1 2 3\n", 1, "got 3 fields"),
        ("0,0,1,1\n1,2,abc,4\n", 2, "expected a number for x2, got 'abc'"),
        ("1,2,nan,4\n", 1, "expected a finite number for x2"),
        ("1,2,3,-inf\n", 1, "expected a finite number for y2"),
        ("1,2,3,1e999\n", 1, "expected finite numbers"),
        ("1,,3,4\n", 1, "empty field"),
        ("1, 2 3, 4\n", 1, "got 3 fields"),
        ("1 2 3 4x\n", 1, "expected a number for y2, got '4x'"),
        ("0,0,1,1\n0,0,1,1,\n", 2, "got 5 fields"),
    ],
)
def test_text_errors_name_file_and_line(text, line, needle):
    with pytest.raises(MapFormatError) as ei:
        parse_vectormap_text(text, "maps/x.vectormap.txt")
    msg = str(ei.value)
    assert msg.startswith(f"maps/x.vectormap.txt:{line}: "), msg
    assert needle in msg
    assert ei.value.line == line and ei.value.source == "maps/x.vectormap.txt"
    assert isinstance(ei.value, InputError) and isinstance(ei.value, ValueError)


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n", "   \n# x\n"])
def test_text_empty_file(text):
    with pytest.raises(MapFormatError, match=r"^e\.txt: no wall segments"):
        parse_vectormap_text(text, "e.txt")


def test_text_zero_length_dropped_with_a_log_line(caplog):
    with caplog.at_level(logging.WARNING, logger="depthnav.map"):
        vm = parse_vectormap_text("0,0,1,0\n5,5,5,5\n1,0,1,1\n2,2,2,2\n", "z.txt")
    assert vm.n_segments == 2
    assert [(r.name, r.levelno, r.getMessage()) for r in caplog.records] == [
        ("depthnav.map", logging.WARNING, "z.txt: dropped 2 zero-length segment(s) at line(s) 2, 4")
    ]
    with pytest.raises(MapFormatError, match=r"^z\.txt: no wall segments left"):
        parse_vectormap_text("3,3,3,3\n", "z.txt")


def test_load_errors(tmp_path):
    with pytest.raises(MapFormatError, match=r"nope\.vectormap\.txt: file not found"):
        load_vectormap(tmp_path / "nope.vectormap.txt")
    bad = tmp_path / "m.vectormap.csv"
    bad.write_text("0,0,1,1\n")
    with pytest.raises(MapFormatError) as ei:
        load_vectormap(bad)
    assert "m.vectormap.csv" in str(ei.value) and ".txt" in str(ei.value) and ".json" in str(ei.value)
    d = tmp_path / "dir.txt"
    d.mkdir()
    with pytest.raises(MapFormatError, match="directory"):
        load_vectormap(d)
    b = tmp_path / "bin.txt"
    b.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(MapFormatError, match="UTF-8"):
        load_vectormap(b)
    with pytest.raises(MapFormatError, match="suffix"):
        save_vectormap(_random_map(3), tmp_path / "x.bin")


def test_load_error_uses_path(tmp_path):
    p = tmp_path / "floor.vectormap.txt"
    p.write_text("0,0,1,1\n0,0,1,1\n0,0,oops,1\n")
    with pytest.raises(MapFormatError, match=rf"^{tmp_path}/floor\.vectormap\.txt:3: expected a number for x2"):
        load_vectormap(p)


# --------------------------------------------------------------------------- JSON errors

_GOOD_SEG = '{"p0": {"x": 0, "y": 0}, "p1": {"x": 1, "y": 1}}'


@pytest.mark.parametrize(
    "text, prefix, needle",
    [
        ("[\n" + _GOOD_SEG + ",\n" + _GOOD_SEG + ",\n" + _GOOD_SEG + ',\n{"p0": {"x": 0, "y": 0}, "p1": {"x": 1, "y": "a"}}\n]',
         "m.json:5: [3].p1.y: ", "expected a number, got the string 'a'"),
        ("[\n" + _GOOD_SEG + ',\n{"p0": {"x": 0, "y": 0},\n "p1": {"x": 1}}\n]', "m.json:4: [1].p1: ", 'missing key "y"'),
        ("[\n" + _GOOD_SEG + ',\n{"p1": {"x": 0, "y": 0}}\n]', "m.json:3: [1]: ", 'missing key "p0"'),
        ("[\n" + _GOOD_SEG + ",\n 7\n]", "m.json:3: [1]: ", "expected a segment object"),
        ('[{"p0": [0, 0], "p1": {"x": 1, "y": 1}}]', "m.json:1: [0].p0: ", "expected a point object"),
        ('[{"p0": {"x": NaN, "y": 0}, "p1": {"x": 1, "y": 1}}]', "m.json:1: [0].p0.x: ", "finite"),
        ('[{"p0": {"x": 0, "y": Infinity}, "p1": {"x": 1, "y": 1}}]', "m.json:1: [0].p0.y: ", "finite"),
        ('[{"p0": {"x": true, "y": 0}, "p1": {"x": 1, "y": 1}}]', "m.json:1: [0].p0.x: ", "got a boolean"),
        ('{"segments": []}', "m.json:1: top level: ", "expected an array"),
        ('{"nodes": [], "edges": []}', "m.json:1: top level: ", "navigation graph"),
        ("[\n" + _GOOD_SEG + ",\n]", "m.json:3:1: ", "invalid JSON"),
        ('[{"p0": {"x": 0 "y": 0}}]', "m.json:1:17: ", "invalid JSON: Expecting ',' delimiter"),
        ("", "m.json:1:1: ", "invalid JSON"),
        ("[]", "m.json: ", "no wall segments"),
    ],
)
def test_json_errors_name_file_path_and_line(text, prefix, needle):
    with pytest.raises(MapFormatError) as ei:
        parse_vectormap_json(text, "m.json")
    msg = str(ei.value)
    assert msg.startswith(prefix), msg
    assert needle in msg, msg
    assert "\n" not in msg


def test_json_zero_length_log_line_names_element_and_line(caplog):
    text = "[\n" + _GOOD_SEG + ',\n{"p0": {"x": 2, "y": 2}, "p1": {"x": 2, "y": 2}}\n]'
    with caplog.at_level(logging.WARNING, logger="depthnav.map"):
        vm = parse_vectormap_json(text, "w.json")
    assert vm.n_segments == 1
    assert caplog.messages == ["w.json: dropped 1 zero-length segment(s) at element(s) [1] (line 3)"]


# --------------------------------------------------------------------------- speed


def test_a_9000_segment_map_round_trips_in_both_formats(tmp_path):
    """A building-sized map (9,000 segments) saved and loaded as text and as JSON comes
    back the same. Its load speed is `make bench`'s map_load_9000 (target 500 ms), not a
    timed test: a wall-clock limit fails on a busy machine whatever the code does."""
    vm = _random_map(9000, seed=3, extremes=False)
    for name in ("big.vectormap.txt", "big.vectormap.json"):
        back = load_vectormap(save_vectormap(vm, tmp_path / name))
        assert back.n_segments == 9000
        np.testing.assert_allclose(back.segments, vm.segments, atol=1e-3)


# --------------------------------------------------------------------------- navigation graph


def _graph() -> NavGraph:
    nodes = (NavNode(10, 0.0, 0.0), NavNode(11, 3.0, 4.0), NavNode(7, 3.0, 0.0), NavNode(12, -1.0, 0.5))
    edges = (
        NavEdge(10, 11, has_door=True, max_speed=0.5, max_clearance=0.45),
        NavEdge(11, 7, has_stairs=True),
        NavEdge(7, 10, has_elevator=True, has_automated_door=True, max_speed=1.25, max_clearance=2.0),
    )
    return NavGraph(nodes, edges)


def test_navgraph_methods():
    g = _graph()
    np.testing.assert_array_equal(g.node_xy(), [[0, 0], [3, 4], [3, 0], [-1, 0.5]])
    assert g.index_of(7) == 2
    with pytest.raises(InputError, match="unknown node id 99"):
        g.index_of(99)
    assert g.neighbors(10) == [11, 7]
    assert g.neighbors(11) == [10, 7]
    assert g.neighbors(12) == []
    assert g.nearest_node(2.9, 0.2) == 7
    assert g.nearest_node(-5, 0) == 12
    np.testing.assert_allclose(g.edge_lengths(), [5.0, 4.0, 3.0])
    np.testing.assert_array_equal(g.edge_indices(), [[0, 1], [1, 2], [2, 0]])
    assert g.n_nodes == 4 and g.n_edges == 3


def test_navgraph_round_trip(tmp_path):
    g = _graph()
    p = save_navgraph(g, tmp_path / "g.navigation.json")
    assert load_navgraph(p) == g
    assert parse_navgraph_json(format_navgraph_json(g)) == g
    data = json.loads(p.read_text())
    assert data["edges"][0] == {
        "s0_id": 10, "s1_id": 11, "has_door": True, "has_stairs": False, "has_elevator": False,
        "has_automated_door": False, "max_speed": 0.5, "max_clearance": 0.45,
    }
    assert data["nodes"][1] == {"id": 11, "loc": {"x": 3.0, "y": 4.0}}


def test_navgraph_round_trip_exact_floats():
    rng = np.random.default_rng(5)
    xy = rng.normal(0, 30, (200, 2))
    nodes = tuple(NavNode(i, x, y) for i, (x, y) in enumerate(xy.tolist()))
    edges = tuple(NavEdge(i, i + 1, max_speed=float(rng.uniform(0.1, 2))) for i in range(199))
    g = NavGraph(nodes, edges)
    back = parse_navgraph_json(format_navgraph_json(g))
    assert back == g
    assert np.array_equal(_bits(back.node_xy()), _bits(xy))


def test_navgraph_optional_keys_default():
    text = '{"nodes": [{"id": 0, "loc": {"x": 0, "y": 0}}, {"id": 1, "loc": {"x": 1, "y": 0}}], "edges": [{"s0_id": 0, "s1_id": 1}]}'
    g = parse_navgraph_json(text)
    assert g.edges[0] == NavEdge(0, 1)
    e = g.edges[0]
    assert not (e.has_door or e.has_stairs or e.has_elevator or e.has_automated_door)
    assert e.max_speed == 0.75 and e.max_clearance == 1.0
    assert isinstance(g.nodes[0].x, float)


_N2 = '{"id": 0, "loc": {"x": 0, "y": 0}},\n  {"id": 1, "loc": {"x": 1, "y": 0}}'


@pytest.mark.parametrize(
    "text, prefix, needle",
    [
        ('{\n "nodes": [\n  ' + _N2 + ',\n  {"id": 1, "loc": {"x": 2, "y": 0}}\n ],\n "edges": []\n}',
         "n.json:5: nodes[2].id: ", "duplicate node id 1 (first at nodes[1])"),
        ('{\n "nodes": [\n  ' + _N2 + '\n ],\n "edges": [\n  {"s0_id": 0, "s1_id": 1},\n  {"s0_id": 1, "s1_id": 42}\n ]\n}',
         "n.json:8: edges[1].s1_id: ", "unknown node id 42"),
        ('{\n "nodes": [\n  ' + _N2 + ',\n  {"id": 2, "loc": {"x": NaN, "y": 0}}\n ],\n "edges": []\n}',
         "n.json:5: nodes[2].loc.x: ", "expected a finite number"),
        ('{\n "nodes": [\n  ' + _N2 + ',\n  {"id": 2, "loc": {"x": 1, "y": "north"}}\n ],\n "edges": []\n}',
         "n.json:5: nodes[2].loc.y: ", "expected a number, got the string 'north'"),
        ('{\n "nodes": [\n  ' + _N2 + ',\n  {"id": "a", "loc": {"x": 1, "y": 2}}\n ],\n "edges": []\n}',
         "n.json:5: nodes[2].id: ", "expected an integer"),
        ('{\n "nodes": [\n  ' + _N2 + ',\n  {"id": 2.5, "loc": {"x": 1, "y": 2}}\n ],\n "edges": []\n}',
         "n.json:5: nodes[2].id: ", "expected an integer"),
        ('{\n "nodes": [\n  ' + _N2 + ',\n  {"loc": {"x": 1, "y": 2}}\n ],\n "edges": []\n}',
         "n.json:5: nodes[2]: ", 'missing key "id"'),
        ('{\n "nodes": [\n  ' + _N2 + ',\n  {"id": 3}\n ],\n "edges": []\n}',
         "n.json:5: nodes[2]: ", 'missing key "loc"'),
        ('{\n "nodes": [\n  ' + _N2 + '\n ],\n "edges": [\n  {"s1_id": 1}\n ]\n}',
         "n.json:7: edges[0]: ", 'missing key "s0_id"'),
        ('{\n "nodes": [\n  ' + _N2 + '\n ],\n "edges": [\n  {"s0_id": 0, "s1_id": 1, "has_door": "yes"}\n ]\n}',
         "n.json:7: edges[0].has_door: ", "expected true or false"),
        ('{\n "nodes": [\n  ' + _N2 + '\n ],\n "edges": [\n  {"s0_id": 0, "s1_id": 1, "max_speed": -1}\n ]\n}',
         "n.json:7: edges[0].max_speed: ", ">= 0"),
        ('{\n "nodes": [\n  ' + _N2 + '\n ],\n "edges": [\n  {"s0_id": 0, "s1_id": 1, "max_clearance": Infinity}\n ]\n}',
         "n.json:7: edges[0].max_clearance: ", "finite"),
        ('{"nodes": [], "edges": []}', "n.json:1: nodes: ", "at least one node"),
        ('{"nodes": {}, "edges": []}', "n.json:1: nodes: ", "expected an array"),
        ('{"nodes": [' + _N2 + "]}", "n.json:1: top level: ", 'missing key "edges"'),
        ("[1, 2]", "n.json:1: top level: ", "expected an object"),
        ('{"nodes": [' + _N2 + '], "edges": [}', "n.json:2:", "invalid JSON"),
    ],
)
def test_navgraph_errors(text, prefix, needle):
    with pytest.raises(MapFormatError) as ei:
        parse_navgraph_json(text, "n.json")
    msg = str(ei.value)
    assert msg.startswith(prefix), msg
    assert needle in msg, msg
    assert "\n" not in msg


def test_navgraph_load_missing(tmp_path):
    with pytest.raises(MapFormatError, match=r"x\.navigation\.json: file not found"):
        load_navgraph(tmp_path / "x.navigation.json")


def test_navgraph_constructor_validation():
    with pytest.raises(InputError, match="no nodes"):
        NavGraph((), ())
    with pytest.raises(InputError, match="duplicates node id 1"):
        NavGraph((NavNode(1, 0, 0), NavNode(1, 1, 1)))
    with pytest.raises(InputError, match=r"edges\[0\]\.s1_id names unknown node id 5"):
        NavGraph((NavNode(1, 0, 0),), (NavEdge(1, 5),))
    with pytest.raises(InputError, match="finite"):
        NavNode(0, math.nan, 0)
    with pytest.raises(InputError, match="integer"):
        NavNode(True, 0, 0)
