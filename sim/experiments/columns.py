"""Per-frame records of a run, kept on disk past a fixed amount of memory.

A 4 km run is over 200,000 frames. Kept as Python lists, each frame's floats, tuples and
pose arrays cost about 800 bytes of objects, and the process grew by some 170 MB over
the run; kept as raw values in memory they still grew it by some 30 MB (128 bytes a
frame), in steps as the arrays doubled. A :class:`Column` keeps the newest rows in one
fixed chunk and appends each full chunk to an anonymous temporary file, so the memory a
run holds for its records does not depend on its length. It reads like the list it
replaces (``append``, ``len``, indexing, ``np.asarray``); reading the whole column maps
the file back.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator

import numpy as np

#: Rows kept in memory per column before they are written to disk.
CHUNK_ROWS = 8192


class Column:
    """Rows of ``width`` values (scalars when ``width`` is None) of one dtype; the newest
    ``chunk`` rows in memory, the older ones in a temporary file."""

    def __init__(self, width: int | None = None, dtype: type | np.dtype = np.float64, chunk: int = CHUNK_ROWS) -> None:
        self._row_shape: tuple[int, ...] = () if width is None else (int(width),)
        self._chunk = np.empty((max(1, int(chunk)),) + self._row_shape, dtype=dtype)
        self._n = 0
        """Rows in the in-memory chunk."""
        self._spilled = 0
        """Rows written to the file."""
        self._file = None

    @property
    def dtype(self) -> np.dtype:
        return self._chunk.dtype

    def append(self, row) -> None:
        """Add one row (a scalar, or ``width`` values)."""
        if self._n == len(self._chunk):
            self._spill()
        self._chunk[self._n] = row
        self._n += 1

    def truncate(self, n: int) -> None:
        """Keep the first ``n`` rows (a no-op when there are no more than ``n``)."""
        n = max(0, int(n))
        if n >= len(self):
            return
        if n >= self._spilled:
            self._n = n - self._spilled
            return
        # Rows on disk past n: the in-memory chunk goes and the file is cut at row n.
        row_bytes = self._chunk[:1].nbytes
        self._file.truncate(n * row_bytes)
        self._spilled, self._n = n, 0

    def _spill(self) -> None:
        if self._file is None:
            self._file = tempfile.TemporaryFile(prefix="depthnav-column-")
        self._file.seek(0, 2)
        self._file.write(self._chunk[: self._n].tobytes())
        self._spilled += self._n
        self._n = 0

    def _on_disk(self) -> np.ndarray:
        if not self._spilled:
            return self._chunk[:0]
        self._file.flush()
        return np.memmap(self._file, dtype=self.dtype, mode="r", shape=(self._spilled,) + self._row_shape)

    @property
    def values(self) -> np.ndarray:
        """All rows so far, in one array (a copy once rows are on disk; a view of the
        chunk before: copy it to keep it past the next ``append``)."""
        if not self._spilled:
            return self._chunk[: self._n]
        return np.concatenate([self._on_disk(), self._chunk[: self._n]])

    def __len__(self) -> int:
        return self._spilled + self._n

    def __bool__(self) -> bool:
        return len(self) > 0

    def __getitem__(self, i):
        if isinstance(i, (int, np.integer)):
            # One row (the loop reads the newest each frame): from the chunk when it is there.
            n = len(self)
            k = int(i) + n if i < 0 else int(i)
            if not 0 <= k < n:
                raise IndexError(f"row {i} out of range for a column of {n} rows")
            if k >= self._spilled:
                return self._chunk[k - self._spilled]
            row = self._on_disk()[k]
            return np.array(row) if self._row_shape else self.dtype.type(row)
        return self.values[i]

    def __iter__(self) -> Iterator:
        return iter(self.values)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        v = self.values
        return v.astype(dtype) if dtype is not None and dtype != v.dtype else (v.copy() if copy else v)
