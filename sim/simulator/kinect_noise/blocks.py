"""The row-block runner: the image split into row blocks, run on a small pool of
threads with the GIL released; every block computes its own halo rows, so blocks need no
synchronisation and the output does not depend on their number."""

from __future__ import annotations

import os
import queue
import threading

import numpy as np

from sim.simulator.kinect_noise.kernels import block

CPUS = os.cpu_count() or 1  # read once: the call costs tens of microseconds here
_tls = threading.local()
_pool_lock = threading.Lock()
_workers: list[queue.SimpleQueue] = []  # one task queue per worker thread


def _reset_pool() -> None:
    """Forget the pool (a forked child has none of its threads)."""
    global _workers
    _workers = []


def _worker(tasks: queue.SimpleQueue) -> None:
    """A block worker: runs (call, done) tasks, reporting None or the exception to done."""
    while True:
        call, done = tasks.get()
        try:
            block(*call)
            done.put(None)
        except BaseException as exc:  # handed to the caller, which raises it
            done.put(exc)


os.register_at_fork(after_in_child=_reset_pool)  # a forked child has no pool threads


def _scratch(index: int, rows: int, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-thread, per-block scratch images (sigma_L, lit depth, theta), reused across frames."""
    cache = getattr(_tls, "scratch", None)
    if cache is None:
        cache = _tls.scratch = {}
    ws = cache.get(index)
    if ws is None or ws[0].shape[0] < rows or ws[0].shape[1] != w:
        ws = cache[index] = tuple(np.zeros((rows, w), dtype=np.float32) for _ in range(3))
    return ws


def run_blocks(n: int, depth: np.ndarray, margin: int, args: tuple, out: np.ndarray) -> None:
    """:func:`~sim.simulator.kinect_noise.kernels.block` over all rows split into n blocks,
    blocks 1.. on pool threads (GIL released); ``args`` are the kernel's arguments after
    the rows and before the scratch images.

    Every row's result depends only on the inputs and the seed, so the output is the same
    for any n.
    """
    h, w = depth.shape
    bounds = [h * c // n for c in range(n + 1)]
    calls = []
    for c in range(n):
        r0, r1 = bounds[c], bounds[c + 1]
        sl, lit, th = _scratch(c, min(h, r1 - r0 + 2 * margin), w)
        calls.append((depth, r0, r1, margin, *args, sl, lit, th, out, False))
    if n == 1:
        block(*calls[0])
        return
    with _pool_lock:
        while len(_workers) < n - 1:
            tasks: queue.SimpleQueue = queue.SimpleQueue()
            name = f"kinect_noise_{len(_workers)}"
            threading.Thread(target=_worker, args=(tasks,), name=name, daemon=True).start()
            _workers.append(tasks)
        workers = _workers[: n - 1]
    # A plain queue hand-off: a thread pool's futures cost tens of microseconds a frame.
    done: queue.SimpleQueue = queue.SimpleQueue()
    for tasks, call in zip(workers, calls[1:], strict=True):
        tasks.put((call, done))
    block(*calls[0])
    errors = [done.get() for _ in workers]
    for exc in errors:
        if exc is not None:
            raise exc
