"""Where a sweep's trials run (:mod:`sim.experiments.sweep`): in this process, on a local
process pool (spawn start method), or as Ray tasks (``max_retries`` for lost workers)
on a cluster or a local Ray instance. Ray is imported only here, when asked for
(``pip install 'depthnav[ray]'``). Every engine hands each finished trial's record to
``on_done`` and what a failed one raised to ``on_error``, so a failing trial does not
lose the others.
"""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import socket
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from autonomy.common.errors import InputError
from sim.experiments.kinds import KINDS, Experiment, experiment, load_experiment

RAY_MAX_RETRIES = 3


# --------------------------------------------------------------------------- workers

_LOADED: dict[Any, tuple[Experiment, Any]] = {}


def _load(source: tuple, kind: str, module: str) -> tuple[Experiment, Any]:
    if kind not in KINDS:  # a kind registered at run time in the parent (plugins, tests)
        KINDS[kind] = module
    if source[0] == "config":
        return experiment(kind), source[1]
    key = (source[1], tuple(source[2]))
    if key not in _LOADED:
        _LOADED[key] = load_experiment(source[1], list(source[2]))
    return _LOADED[key]


def execute_trial(source: tuple, kind: str, module: str, spec: dict) -> dict:
    """Run one trial in whatever process this is; the trials.jsonl record."""
    exp, cfg = _load(source, kind, module)
    t0 = time.perf_counter()
    result = exp.trial(cfg, spec)
    return {
        "id": spec["id"],
        "spec": spec,
        "result": result,
        "wall_s": round(time.perf_counter() - t0, 4),
        "host": socket.gethostname(),
        "pid": os.getpid(),
    }


def _worker_init() -> None:
    # The parent handles Ctrl-C and stops the workers itself.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# --------------------------------------------------------------------------- engines


def _deliver(result: Callable[[], dict], spec: dict, on_done, on_error) -> None:
    """Hand a trial's record to ``on_done``, or what it raised to ``on_error``: a failing
    trial must not lose the others (Ctrl-C is not caught)."""
    try:
        rec = result()
    except Exception as exc:  # noqa: BLE001 - any trial error, e.g. a RayTaskError wrapping it
        on_error(spec, exc)
        return
    on_done(rec)


def run_local(source, kind, module, specs, workers, on_done, on_error) -> None:
    """Run ``specs`` here (``workers`` 1) or on a process pool of ``workers``."""
    pool_map(functools.partial(execute_trial, source, kind, module), specs, workers, on_done, on_error)


def pool_map(fn: Callable[[dict], dict], specs: list[dict], workers: int, on_done, on_error) -> None:
    """``fn(spec)`` for every spec, here (``workers`` 1) or on a process pool of
    ``workers`` (spawn start method: each worker imports what ``fn`` needs afresh, no
    GL or thread state is forked); each result to ``on_done`` as it finishes, each
    failure to ``on_error``. Ctrl-C stops the workers and is raised again."""
    if workers <= 1:
        for s in specs:
            _deliver(lambda s=s: fn(s), s, on_done, on_error)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    pool = ProcessPoolExecutor(max_workers=min(workers, len(specs)), mp_context=mp.get_context("spawn"), initializer=_worker_init)
    try:
        futs = {pool.submit(fn, s): s for s in specs}
        for fut in as_completed(futs):
            _deliver(fut.result, futs[fut], on_done, on_error)
    except KeyboardInterrupt:
        procs = list(getattr(pool, "_processes", {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:  # our own workers, by their handles
            if p.is_alive():
                p.terminate()
        raise
    pool.shutdown(wait=True)


def _import_ray():
    try:
        import ray
    except ImportError:
        raise InputError("--engine ray: Ray is not installed (pip install 'depthnav[ray]')") from None
    return ray


def _init_ray(ray, address: str | None, workers: int) -> None:
    """Connect to the cluster at ``address``, or start a local Ray with ``workers`` CPUs."""
    if address:
        try:
            ray.init(address=address, log_to_driver=False)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise InputError(f"--address {address}: cannot connect to a Ray cluster ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
        return
    # Local workers must import this project (and anything on our path) as we do.
    old = os.environ.get("PYTHONPATH")
    paths = [p for p in sys.path if p and Path(p).is_dir()]
    os.environ["PYTHONPATH"] = os.pathsep.join(dict.fromkeys([os.getcwd(), *paths]))
    try:
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, configure_logging=False)
    finally:
        if old is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = old


@contextlib.contextmanager
def ray_session(address: str | None, workers: int):
    """Ray connected (to the cluster at ``address``, or a local Ray of ``workers`` CPUs)
    for the block, and shut down after it if this started it: a sweep connects before
    any long preparation, so a cluster that is not there is a one-line error at once."""
    ray = _import_ray()
    started = not ray.is_initialized()
    if started:
        _init_ray(ray, address, workers)
    try:
        yield
    finally:
        if started:
            ray.shutdown()


def run_ray(source, kind, module, specs, workers, address, on_done, on_error) -> None:
    """Run ``specs`` as Ray tasks on the cluster at ``address`` (or a local Ray of ``workers`` CPUs)."""
    ray = _import_ray()
    started = False
    if not ray.is_initialized():
        _init_ray(ray, address, workers)
        started = True
    remote = ray.remote(num_cpus=1, max_retries=RAY_MAX_RETRIES)(execute_trial)
    refs = {}
    try:
        for s in specs:
            refs[remote.remote(source, kind, module, s)] = s
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for r in ready:
                _deliver(lambda r=r: ray.get(r), refs[r], on_done, on_error)
    except KeyboardInterrupt:
        for r in refs:
            try:
                ray.cancel(r, force=True)
            except Exception:  # noqa: BLE001 - best effort
                pass
        raise
    finally:
        if started:
            ray.shutdown()
