"""The one exception type for user mistakes (bad file, bad key, bad argument).

The CLI turns an :class:`InputError` into a one-line message on stderr and exit code 2;
anything else is a bug and exits 1.
"""

from __future__ import annotations


class InputError(ValueError):
    """A user-facing input error; ``str(err)`` is the whole one-line message."""
