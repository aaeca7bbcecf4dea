"""Atomic file writes: a reader of the file, or a process that starts after a crash, sees
the old content or the new, never a part.

The new content goes to a temporary file beside the target (same directory, so the same
file system), is flushed to disk, then renamed over the target (``os.replace``, atomic on
POSIX); on any exception, KeyboardInterrupt included, the temporary file is removed and an
existing target is left as it was. The file gets the mode a plain ``open(path, "w")``
gives a new file (``0o666`` less the umask), not :func:`tempfile.mkstemp`'s private
``0o600``.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from autonomy.common.errors import InputError


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A fresh, empty temporary file beside ``path`` to write by name (for writers that
    want a path, such as a memory map); renamed onto ``path`` when the block ends normally,
    removed when it raises. The parent directory must exist."""
    p = Path(path)
    tmp, fd = _create_beside(p)
    os.close(fd)
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, p)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _fsync_dir(p.parent)


def atomic_write(path: str | os.PathLike[str], write: Callable[[BinaryIO], object]) -> Path:
    """Write ``path`` atomically: ``write(f)`` fills a binary file that then replaces
    ``path`` whole (see the module docstring). Returns ``path`` as a Path."""
    p = Path(path)
    with atomic_path(p) as tmp, open(tmp, "wb") as f:
        write(f)
    return p


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see the module docstring)."""
    return atomic_write(path, lambda f: f.write(text.encode(encoding)))


def output_path(path: str | os.PathLike[str], name: str = "out", directory: bool = False) -> Path:
    """``path`` ready to be written (a file, or with ``directory`` a directory), checked
    before long work that ends in writing it: the directory made, and a directory given
    for a file, a path under a file or a directory that cannot be written is a one-line
    :class:`InputError` naming ``name`` (the argument or option)."""
    p = Path(path)
    d = p if directory else p.parent
    if not directory and p.is_dir():
        raise InputError(f"{name} {p}: is a directory (expected a file name)")
    if directory and p.exists() and not p.is_dir():
        raise InputError(f"{name} {p}: is a file (expected a directory)")
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{name} {p}: cannot make the directory {d} ({e.strerror or e})") from None
    if not os.access(d, os.W_OK | os.X_OK):
        raise InputError(f"{name} {p}: the directory {d} is not writable")
    return p


def _create_beside(p: Path) -> tuple[Path, int]:
    """Create ``.<name>.<random>.tmp`` in ``p``'s directory exclusively, mode 0o666 less
    the umask (the kernel applies it); its path and an open descriptor."""
    while True:
        tmp = p.with_name(f".{p.name}.{secrets.token_hex(4)}.tmp")
        try:
            return tmp, os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        except OSError as e:  # named for the file the caller asked for, not the temporary one
            raise OSError(e.errno, e.strerror, str(p)) from None


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(directory: Path) -> None:
    """Make the rename durable; best effort (not every file system syncs a directory)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
