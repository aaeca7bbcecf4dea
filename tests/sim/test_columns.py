"""The runner's per-frame record columns behave as the lists they replace, and hold a
fixed amount of memory however long the run."""

import tracemalloc

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from sim.experiments.columns import Column

finite = st.floats(-1e6, 1e6, allow_nan=False)


@given(st.lists(finite, max_size=300), st.integers(1, 8))
def test_scalar_column_matches_a_list(values, chunk):
    c = Column(chunk=chunk)
    for v in values:
        c.append(v)
    assert len(c) == len(values) and bool(c) == bool(values)
    np.testing.assert_array_equal(np.asarray(c), np.array(values, dtype=np.float64))
    for i in (0, len(values) // 2, -1, -len(values)):
        if values:
            assert c[i] == values[i] and isinstance(c[i], np.float64)
    np.testing.assert_array_equal(c[1 : 1 + len(values) // 2], np.array(values[1 : 1 + len(values) // 2]))


@given(st.lists(st.tuples(finite, finite, finite), max_size=200), st.integers(1, 5))
def test_row_column_matches_a_list_of_rows(rows, chunk):
    c = Column(3, chunk=chunk)
    for r in rows:
        c.append(np.array(r))
    expected = np.array(rows, dtype=np.float64).reshape(-1, 3)
    np.testing.assert_array_equal(np.array(c), expected)
    assert [tuple(r) for r in c] == [tuple(r) for r in expected]
    if rows:
        np.testing.assert_array_equal(c[0], expected[0])
        np.testing.assert_array_equal(c[-1], expected[-1])


@given(st.lists(st.tuples(finite, finite), max_size=60), st.integers(1, 6), st.integers(0, 70), st.lists(st.tuples(finite, finite), max_size=10))
def test_truncate_keeps_the_first_rows_and_appends_after_them(rows, chunk, n, more):
    c = Column(2, chunk=chunk)
    for r in rows:
        c.append(np.array(r))
    c.truncate(n)
    for r in more:
        c.append(np.array(r))
    expected = np.array(rows[:n] + more, dtype=np.float64).reshape(-1, 2)
    assert len(c) == len(expected)
    np.testing.assert_array_equal(np.asarray(c), expected)
    if len(expected):
        np.testing.assert_array_equal(c[-1], expected[-1])
        np.testing.assert_array_equal(c[0], expected[0])


def test_indexing_past_the_end_is_an_index_error():
    c = Column(chunk=2)
    for v in range(5):
        c.append(float(v))
    for i in (5, -6):
        try:
            c[i]
        except IndexError:
            continue
        raise AssertionError(f"row {i} of 5 did not raise")


def test_typed_column_keeps_its_dtype_and_converts_on_request():
    c = Column(4, np.int32, chunk=1)
    c.append((1, 2, 3, 4))
    c.append((5, 6, 7, 8))
    assert np.asarray(c).dtype == np.int32
    np.testing.assert_array_equal(np.array(c, dtype=np.float64)[:, 0], [1.0, 5.0])
    t = Column(None, np.float32)
    t.append(0.0015)
    assert abs(float(np.median(t)) - 0.0015) < 1e-9


def test_a_view_taken_before_more_rows_keeps_its_values():
    c = Column(chunk=1)
    c.append(1.0)
    v = c.values.copy()
    for k in range(10):
        c.append(float(k))
    assert v.tolist() == [1.0] and len(c) == 11


def test_memory_does_not_grow_with_the_rows():
    """200,000 pose rows are 4.8 MB of values; the column holds one chunk of them."""
    tracemalloc.start()
    try:
        c = Column(3, chunk=1000)
        before = tracemalloc.get_traced_memory()[0]
        for k in range(200_000):
            c.append((k, 0.0, 0.0))
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(c) == 200_000 and held < 200_000
    assert np.asarray(c)[-1, 0] == 199_999 and c[123_456][0] == 123_456
