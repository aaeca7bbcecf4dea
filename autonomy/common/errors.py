"""The one exception type for user mistakes (bad file, bad key, bad argument).

The CLI turns an :class:`InputError` into a one-line message on stderr and exit code 2;
anything else is a bug and exits 1.
"""

from __future__ import annotations

import math


class InputError(ValueError):
    """A user-facing input error; ``str(err)`` is the whole one-line message."""


def require_positive(cfg: object, prefix: str, *names: str) -> None:
    """Raise an InputError naming ``prefix.name`` unless each field is a finite number > 0."""
    for name in names:
        v = getattr(cfg, name)
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"{prefix}{name}: expected a positive number, got {v!r}")


def require_int(cfg: object, prefix: str, *names: str, minimum: int = 1) -> None:
    """Raise an InputError naming ``prefix.name`` unless each field is an integer >= minimum."""
    for name in names:
        v = getattr(cfg, name)
        if isinstance(v, bool) or not (isinstance(v, int) and v >= minimum):
            raise InputError(f"{prefix}{name}: expected an integer >= {minimum}, got {v!r}")


def require_non_negative(cfg: object, prefix: str, *names: str) -> None:
    """Raise an InputError naming ``prefix.name`` unless each field is a finite number >= 0."""
    for name in names:
        v = getattr(cfg, name)
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise InputError(f"{prefix}{name}: expected a number >= 0, got {v!r}")
