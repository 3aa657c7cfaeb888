"""Whole-array geometry on every core.

Shapely 2's vectorised functions release the GIL while GEOS works, so one array of
geometries split into a slice per core and handed to threads runs that many times
faster, with the same result: each element's operation is independent of the others.

One thing two threads must not share: a prepared geometry (:func:`shapely.prepare`).
GEOS keeps working state in it that its predicates change, so two threads testing the
same prepared geometry at once can crash the process.  The project never prepares a
geometry it was given (it prepares :func:`prepared_copy` instead), nor hands one
geometry to shapely's ``contains_xy`` or ``intersects_xy`` with many points (which
prepares it for good), and :func:`elementwise` keeps an operation whose first operand
holds a prepared geometry in one thread.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor, wait
from contextlib import contextmanager

import numpy as np
import shapely

# below this many elements a split costs more than it saves
PARALLEL_MIN = 64

# one pool for the process, made on first use: a mosaic makes hundreds of these calls.
# A forked child (a Dask worker) does not inherit the parent's threads, so it starts
# without a pool and makes its own.
_pool: ThreadPoolExecutor | None = None
_pool_workers = 0
_pool_lock = threading.Lock()
# set in the pool's threads while they run a slice or a call: a call made from there
# runs in that thread, as waiting on the pool from inside it could wait for ever
_on_pool = threading.local()


def _forget_pool() -> None:
    global _pool, _pool_workers
    _pool, _pool_workers = None, 0


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def _shared_pool(workers: int) -> ThreadPoolExecutor:
    """The process's pool, with at least ``workers`` threads."""
    global _pool, _pool_workers
    with _pool_lock:
        if _pool is None or _pool_workers < workers:
            old = _pool
            _pool, _pool_workers = ThreadPoolExecutor(workers, thread_name_prefix="elementwise"), workers
            if old is not None:
                old.shutdown(wait=False)
        return _pool


def _on_the_pool(call):
    """``call`` wrapped to run with the pool-thread flag set."""

    def run(*args):
        _on_pool.active = True
        try:
            return call(*args)
        finally:
            _on_pool.active = False

    return run


def _nested() -> bool:
    """Whether this thread is one of the pool's, running a slice or a call."""
    return getattr(_on_pool, "active", False)


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def _holds_prepared(operand: np.ndarray) -> bool:
    """Whether an operand of geometries holds a prepared one."""
    return operand.dtype == object and bool(shapely.is_prepared(operand).any())


def own_copy(geometry: shapely.Geometry | np.ndarray) -> shapely.Geometry | np.ndarray:
    """A new geometry with exactly the same coordinates (or one for each of an array of
    them), sharing no GEOS state with the given one: never prepared.

    Parameters
    ----------
    geometry : shapely.Geometry or numpy.ndarray
        Any geometry, or an array of them.

    Returns
    -------
    shapely.Geometry or numpy.ndarray
        The copy, or an array of copies.
    """
    return shapely.from_wkb(shapely.to_wkb(geometry))


def prepared_copy(geometry: shapely.Geometry | np.ndarray) -> shapely.Geometry | np.ndarray:
    """A prepared copy of ``geometry`` (or of each of an array of them), for the caller's
    own thread.

    Preparing speeds up testing many geometries against one, but a prepared geometry is
    not safe to use from two threads at once; a copy leaves the given geometry as it
    was, free to be used anywhere.

    Parameters
    ----------
    geometry : shapely.Geometry or numpy.ndarray
        Any geometry, or an array of them.

    Returns
    -------
    shapely.Geometry or numpy.ndarray
        The same geometry (the same coordinates, exactly), a new object, prepared; or
        an array of such copies.
    """
    own = own_copy(geometry)
    shapely.prepare(own)
    return own


def elementwise(operation, *arrays: np.ndarray, **kwargs) -> np.ndarray:
    """``operation(*arrays, **kwargs)`` for an element-by-element ``operation`` (such as
    ``shapely.difference``), its arrays cut into one slice per core run in threads.

    Parameters
    ----------
    operation : callable
        Takes equal-length 1-d arrays and returns one result per element; it must
        release the GIL to gain anything (shapely's functions do).  Called from inside
        a slice or a :func:`side_by_side` call, ``elementwise`` runs in that thread; so
        it does when the first operand holds a prepared geometry (shapely's predicates
        use it, and two threads must not).
    *arrays : 1-d ndarrays of one length
        The operands.
    **kwargs
        Passed on to every call.

    Returns
    -------
    ndarray
        The same as ``operation(*arrays, **kwargs)``.
    """
    n = len(arrays[0])
    workers = min(usable_cores(), n // PARALLEL_MIN)
    if workers < 2 or _nested() or _holds_prepared(arrays[0]):
        return operation(*arrays, **kwargs)
    bounds = np.linspace(0, n, workers + 1).astype(np.int64)
    slices = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    pool = _shared_pool(workers)
    parts = list(pool.map(_on_the_pool(lambda s: operation(*(a[s] for a in arrays), **kwargs)), slices))
    return np.concatenate(parts)


def side_by_side(*calls):
    """The results of independent zero-argument ``calls``, run at the same time: the
    first in this thread, the others on the process's pool (for whole-array NumPy and
    SciPy work, which lets go of the GIL while it computes).

    Parameters
    ----------
    *calls : callables
        Each takes no argument; none may depend on another's effects.  Those on the
        pool that call :func:`elementwise` or ``side_by_side`` run that in their own
        thread (waiting on the pool from inside it could wait for ever).

    Returns
    -------
    list
        ``[call() for call in calls]``; an exception in any call is raised here.
    """
    cores = usable_cores()
    if len(calls) < 2 or cores < 2 or _nested():
        return [call() for call in calls]
    pool = _shared_pool(cores)
    later = [pool.submit(_on_the_pool(call)) for call in calls[1:]]
    try:
        first = calls[0]()
    finally:
        done = [f.result() for f in later]  # waits for the others even when the first failed
    return [first, *done]


def in_order(calls: Iterable[Callable], ahead: int | None = None) -> Iterator:
    """The results of independent zero-argument ``calls``, one at a time and in order,
    while the next ones run on the process's pool: the caller works on each result as
    the pool works on those after it.

    Parameters
    ----------
    calls : iterable of callables
        Each takes no argument; none may depend on another's effects.  Taken from the
        iterable only as the pool makes room, so no more than ``ahead`` results wait.
    ahead : int, optional
        How many calls run (or wait, done) at once; default the usable cores.

    Yields
    ------
    object
        ``call()`` for each call, in the calls' order; an exception in a call is raised
        here, after the calls still running have finished.
    """
    cores = usable_cores()
    if cores < 2 or _nested():
        for call in calls:
            yield call()
        return
    pool = _shared_pool(cores)
    pending = iter(calls)
    running: deque = deque()
    try:
        for call in itertools.islice(pending, cores if ahead is None else max(1, ahead)):
            running.append(pool.submit(_on_the_pool(call)))
        while running:
            result = running.popleft().result()
            for call in itertools.islice(pending, 1):  # its place goes to the next call
                running.append(pool.submit(_on_the_pool(call)))
            yield result
    finally:
        for future in running:  # none left working on what the caller goes on to change
            future.cancel()
        wait(running)


@contextmanager
def on_its_own_thread(call: Callable, *args) -> Iterator[Callable]:
    """``call(*args)`` run on a thread of its own while the ``with`` block runs (not on
    the process's pool, whose calls the block may wait on).

    Parameters
    ----------
    call : callable
        Independent of what the block does; it should let go of the GIL to gain anything.
    *args
        Its arguments.

    Yields
    ------
    callable
        ``result()``: waits for the call and returns what it returned (its exception is
        raised there).  Leaving the block waits for the call too.
    """
    with ThreadPoolExecutor(1, thread_name_prefix="beside") as pool:
        yield pool.submit(call, *args).result


__all__ = [
    "PARALLEL_MIN",
    "usable_cores",
    "elementwise",
    "side_by_side",
    "on_its_own_thread",
    "own_copy",
    "prepared_copy",
    "in_order",
]
