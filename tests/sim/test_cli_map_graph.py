"""``depthnav map graph`` and the free-space part of ``depthnav map check``."""

from __future__ import annotations

import json

from autonomy.common.geometry import WallIndex
from autonomy.maps.navgraph import load_navgraph
from autonomy.maps.vectormap import load_vectormap, save_vectormap
from sim.cli import main
from sim.scenario import ASSETS_DIR
from tests.helpers import box_segments, err_line, segments_map

SMALL = ASSETS_DIR / "small_floor.vectormap.txt"


def test_map_graph_writes_a_navigation_json_that_keeps_the_clearance(tmp_path, capsys):
    out = tmp_path / "g.navigation.json"
    png = tmp_path / "g.png"
    assert main(["map", "graph", str(SMALL), "--out", str(out), "--quality", "--png", str(png)]) == 0
    text = capsys.readouterr().out
    assert "coverage within 1.5 m" in text and "stretch" in text
    g = load_navgraph(out)
    assert json.loads(out.read_text())["depthnav"]["key"]
    clear = WallIndex(load_vectormap(SMALL).segments).clearances(g.edge_segments(), 5.0)
    assert clear.min() >= 0.35
    assert png.stat().st_size > 0


def test_map_graph_beside_the_map_and_a_bigger_robot(tmp_path, capsys):
    p = tmp_path / "hall.vectormap.txt"
    save_vectormap(segments_map(box_segments(0, 0, 12, 6)), p)
    assert main(["map", "graph", str(p), "--robot-radius", "0.5"]) == 0
    g = load_navgraph(tmp_path / "hall.navigation.json")
    clear = WallIndex(load_vectormap(p).segments).clearances(g.edge_segments(), 5.0)
    assert clear.min() >= 0.55
    capsys.readouterr()
    # the default output exists now: refuse to overwrite it without --force
    assert main(["map", "graph", str(p)]) == 2
    assert "--force" in err_line(capsys)
    assert main(["map", "graph", str(p), "--force"]) == 0


def test_map_check_reports_free_space_regions_and_graph(tmp_path, capsys):
    p = tmp_path / "two.vectormap.txt"
    save_vectormap(segments_map(box_segments(0, 0, 20, 10) + box_segments(14, 6, 18, 9)), p)
    assert main(["map", "check", str(p)]) == 0
    out = capsys.readouterr().out
    assert "in 2 region(s)" in out and "navigation graph:" in out and "2 component(s)" in out


def test_bad_maps_give_one_line_errors(tmp_path, capsys):
    closed = tmp_path / "closed.vectormap.txt"
    save_vectormap(segments_map(box_segments(0, 0, 0.5, 0.5)), closed)
    assert main(["map", "graph", str(closed), "--out", str(tmp_path / "x.json")]) == 2
    assert "only the outside of the building is free" in err_line(capsys)
    degenerate = tmp_path / "degenerate.vectormap.txt"
    degenerate.write_text("1, 1, 1, 1\n2, 2, 2, 2\n")
    assert main(["map", "graph", str(degenerate)]) == 2
    assert "degenerate.vectormap.txt" in err_line(capsys)
    empty = tmp_path / "empty.vectormap.txt"
    empty.write_text("")
    assert main(["map", "check", str(empty)]) == 2
    assert "empty.vectormap.txt" in err_line(capsys)
    assert main(["map", "graph", str(SMALL), "--robot-radius", "-1"]) == 2
    assert "--robot-radius" in err_line(capsys)
    # a single wall: free space only around it, nothing inside
    line = tmp_path / "line.vectormap.txt"
    line.write_text("0, 0, 10, 0\n")
    assert main(["map", "graph", str(line), "--out", str(tmp_path / "y.json")]) == 2
    assert "robot" in err_line(capsys)


def test_map_graph_compares_with_a_hand_made_graph_on_the_same_pairs(tmp_path, capsys):
    hand = ASSETS_DIR / "small_floor.navigation.json"
    assert main(["map", "graph", str(SMALL), "--out", str(tmp_path / "g.json"), "--compare", str(hand)]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "point pairs" in ln]
    assert len(lines) == 2 and lines[0].lstrip().startswith("generated:") and str(hand) in lines[1]
    pairs = {ln.rsplit("(", 1)[1] for ln in lines}
    assert len(pairs) == 1  # measured on the same point pairs


def test_map_check_lists_the_loader_findings_and_convert_rescales(tmp_path, capsys):
    dup = tmp_path / "dup.vectormap.txt"
    dup.write_text("0, 0, 10, 0\n10, 0, 10, 6\n10, 6, 0, 6\n0, 6, 0, 0\n0, 0, 10, 0\n")
    assert main(["map", "check", str(dup)]) == 0
    out = capsys.readouterr().out
    assert "warning:" in out and "duplicate" in out and "line(s) 5" in out
    mm = tmp_path / "mm.vectormap.txt"
    mm.write_text("0, 0, 10000, 0\n10000, 0, 10000, 6000\n10000, 6000, 0, 6000\n0, 6000, 0, 0\n")
    assert main(["map", "check", str(mm)]) == 2
    assert "--scale 0.001" in err_line(capsys)
    m = tmp_path / "m.vectormap.txt"
    assert main(["map", "convert", str(mm), str(m), "--scale", "0.001"]) == 0
    assert load_vectormap(m).extent() == (0.0, 0.0, 10.0, 6.0)


def test_an_open_site_is_detected_or_declared_and_refused_with_closed(tmp_path, capsys):
    lot = tmp_path / "lot.vectormap.txt"
    # two walls that close nothing: a lot between them
    save_vectormap(segments_map([(0, 0, 30, 0), (0, 20, 30, 20), (0, 0, 0, 3)]), lot)
    assert main(["map", "check", str(lot)]) == 0
    out = capsys.readouterr().out
    assert "open map (detected" in out and "in 1 region(s)" in out
    free = float(out.split("radius 0.30 m: ")[1].split(" m2")[0])
    assert 0.9 * 30 * 20 < free < 30 * 20
    assert main(["map", "graph", str(lot), "--open", "--out", str(tmp_path / "g.json")]) == 0
    assert "open map (--open)" in capsys.readouterr().out
    assert load_navgraph(tmp_path / "g.json").n_nodes > 0
    assert main(["map", "check", str(lot), "--closed"]) == 2
    assert "--open" in err_line(capsys)
    assert main(["map", "check", str(lot), "--open", "--closed"]) == 2
    assert "not allowed with" in err_line(capsys)
