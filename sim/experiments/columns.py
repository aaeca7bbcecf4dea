"""Growable typed arrays for a run's per-frame records.

A 4 km run is over 200,000 frames. Kept as Python lists, each frame's floats, tuples and
pose arrays cost about 800 bytes of objects, and the process grows by some 170 MB over
the run. A :class:`Column` keeps the same records as raw values in one numpy array that
doubles when full: a few bytes per value, and a list-like interface (``append``,
``len``, indexing, ``np.asarray``) for the code that reads them.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np


class Column:
    """Rows of ``width`` values (scalars when ``width`` is None) of one dtype."""

    def __init__(self, width: int | None = None, dtype: type | np.dtype = np.float64, capacity: int = 1024) -> None:
        shape = (max(1, capacity),) if width is None else (max(1, capacity), width)
        self._data = np.empty(shape, dtype=dtype)
        self._n = 0

    def append(self, row) -> None:
        """Add one row (a scalar, or ``width`` values)."""
        if self._n == len(self._data):
            grown = np.empty((2 * len(self._data),) + self._data.shape[1:], dtype=self._data.dtype)
            grown[: self._n] = self._data[: self._n]
            self._data = grown
        self._data[self._n] = row
        self._n += 1

    @property
    def values(self) -> np.ndarray:
        """The rows so far (a view: copy it to keep it past the next ``append``)."""
        return self._data[: self._n]

    def __len__(self) -> int:
        return self._n

    def __bool__(self) -> bool:
        return self._n > 0

    def __getitem__(self, i):
        return self.values[i]

    def __iter__(self) -> Iterator:
        return iter(self.values)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        v = self.values
        return v.astype(dtype) if dtype is not None and dtype != v.dtype else (v.copy() if copy else v)
