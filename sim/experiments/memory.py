"""The process's resident memory, and giving freed heap memory back to the system.

A long run frees as much as it allocates, yet its resident memory rises in steps: glibc's
malloc keeps freed chunks inside its heap, and after a large temporary array has been
freed (the relocalization's whole-map search holds some of 10 MB and more) it raises its
mmap threshold, so that later arrays of that size come from the heap too. The heap's
high-water mark then stays resident although its middle is free: a 4 km run held 22 MB
of such free heap 700 s in, which ``malloc_trim`` handed back at once.
:func:`release_free_memory` does that (glibc only; elsewhere nothing), and the closed
loop calls it every ``RSS_EVERY`` frames, so what a long run reports is the memory it
uses.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from functools import cache


def resident_mb() -> float:
    """This process's resident memory in MB (Linux /proc; elsewhere its peak so far)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


@cache
def _malloc_trim():
    """glibc's ``malloc_trim``, or None where the C library has none (musl, macOS)."""
    try:
        fn = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None
    fn.argtypes, fn.restype = [ctypes.c_size_t], ctypes.c_int
    return fn


def release_free_memory() -> bool:
    """Return the heap's free pages to the system (``malloc_trim(0)``, a few ms on a
    run's heap); True when memory was released, False when none was or the C library
    cannot."""
    fn = _malloc_trim()
    return bool(fn(0)) if fn is not None else False
