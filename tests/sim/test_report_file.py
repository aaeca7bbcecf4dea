"""The one writer of run reports: strict JSON, whole or not at all."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.experiments.report_file import json_safe, write_json


def test_nan_and_infinities_become_null_and_numpy_plain_python(tmp_path: Path) -> None:
    doc = {
        "nan": math.nan, "inf": -math.inf, "f32": np.float32(1.5), "i64": np.int64(7), "flag": np.bool_(True),
        "arr": np.array([[1.0, np.nan], [2.0, 3.0]]), "tuple": (1, np.float64(np.inf)), "text": "a", "none": None,
    }
    p = write_json(tmp_path / "report.json", doc)
    text = p.read_text(encoding="utf-8")
    back = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c} written"))
    assert back == {
        "nan": None, "inf": None, "f32": 1.5, "i64": 7, "flag": True,
        "arr": [[1.0, None], [2.0, 3.0]], "tuple": [1, None], "text": "a", "none": None,
    }
    assert text.endswith("\n") and [q.name for q in tmp_path.iterdir()] == ["report.json"]


def test_a_failed_write_leaves_the_report_before(tmp_path: Path) -> None:
    p = write_json(tmp_path / "report.json", {"frames": 1})
    with pytest.raises(TypeError):
        write_json(p, {"frames": 2, "bad": object()})  # not serializable: fails mid-way
    assert json.loads(p.read_text(encoding="utf-8")) == {"frames": 1}
    assert [q.name for q in tmp_path.iterdir()] == ["report.json"]


@given(st.recursive(st.floats() | st.integers() | st.text(max_size=5) | st.none(), lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=4), c, max_size=4)))
def test_json_safe_always_gives_strict_json_that_keeps_finite_values(obj) -> None:
    text = json.dumps(json_safe(obj), allow_nan=False)

    def same(a, b) -> bool:
        if isinstance(a, float) and not math.isfinite(a):
            return b is None
        if isinstance(a, (list, tuple)):
            return isinstance(b, list) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
        if isinstance(a, dict):
            return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
        return a == b

    assert same(obj, json.loads(text))


def test_dataclasses_write_as_their_fields_and_a_missing_folder_is_made(tmp_path: Path) -> None:
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class Row:
        name: str
        error_m: float

    p = write_json(tmp_path / "new" / "eval.json", {"rows": [Row("a", math.nan)], 3: Row("b", 0.5)})
    assert json.loads(p.read_text(encoding="utf-8")) == {"rows": [{"name": "a", "error_m": None}], "3": {"name": "b", "error_m": 0.5}}


def test_a_configuration_keeps_its_infinities_as_text() -> None:
    from sim.experiments.report_file import config_json

    cfg = {"max_range_m": math.inf, "route": [(0.0, 1.0), (2.0, -math.inf)], "name": "x"}
    assert json.loads(json.dumps(config_json(cfg), allow_nan=False)) == {"max_range_m": "inf", "route": [[0.0, 1.0], [2.0, "-inf"]], "name": "x"}
