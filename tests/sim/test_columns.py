"""The runner's per-frame record columns behave as the lists they replace."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from sim.experiments.columns import Column

finite = st.floats(-1e6, 1e6, allow_nan=False)


@given(st.lists(finite, max_size=300), st.integers(1, 8))
def test_scalar_column_matches_a_list(values, capacity):
    c = Column(capacity=capacity)
    for v in values:
        c.append(v)
    assert len(c) == len(values) and bool(c) == bool(values)
    np.testing.assert_array_equal(np.asarray(c), np.array(values, dtype=np.float64))
    if values:
        assert c[-1] == values[-1]
        np.testing.assert_array_equal(c[1 : 1 + len(values) // 2], np.array(values[1 : 1 + len(values) // 2]))


@given(st.lists(st.tuples(finite, finite, finite), max_size=200))
def test_row_column_matches_a_list_of_rows(rows):
    c = Column(3, capacity=2)
    for r in rows:
        c.append(np.array(r))
    expected = np.array(rows, dtype=np.float64).reshape(-1, 3)
    np.testing.assert_array_equal(np.array(c), expected)
    assert [tuple(r) for r in c] == [tuple(r) for r in expected]


def test_typed_column_keeps_its_dtype_and_converts_on_request():
    c = Column(4, np.int32)
    c.append((1, 2, 3, 4))
    c.append((5, 6, 7, 8))
    assert np.asarray(c).dtype == np.int32
    np.testing.assert_array_equal(np.array(c, dtype=np.float64)[:, 0], [1.0, 5.0])
    t = Column(None, np.float32)
    t.append(0.0015)
    assert abs(float(np.median(t)) - 0.0015) < 1e-9


def test_a_view_taken_before_growth_keeps_its_values():
    c = Column(capacity=1)
    c.append(1.0)
    v = c.values.copy()
    for k in range(10):
        c.append(float(k))
    assert v.tolist() == [1.0] and len(c) == 11
