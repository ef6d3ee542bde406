"""Process helpers shared by the packages: the one process pool, and a process's resident memory.

:class:`ProcessPool` is how the package runs work in other processes (the diagnosis's candidate fits,
the finite-difference columns of its least squares, the TPE fit's extra Optuna workers, the lab's
experiments). With ``workers <= 1`` everything runs in this process, in order. With the ``"fork"``
start method the workers inherit the parent's objects: what a task needs beyond its (pickled)
arguments is given as ``shared`` and read in the worker with :func:`shared`, so built models and
recordings are never pickled. ``"spawn"`` starts fresh interpreters (tasks and arguments are pickled).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

from battery_predictor.errors import BatteryPredictorError

#: What the parent of a ``fork`` pool gave as ``shared`` (inherited by its workers).
_SHARED: dict[str, Any] = {}


def shared(key: str) -> Any:
    """In a task of a :class:`ProcessPool`: the value the pool was given as ``shared[key]``."""
    return _SHARED[key]


class ProcessPool:
    """A pool of ``workers`` processes, or this process alone when ``workers <= 1`` (a context manager).

    Parameters
    ----------
    workers : int
        Worker processes; 1 or fewer runs every task in this process, in order.
    start_method : str
        ``"fork"`` (workers inherit ``shared`` and the parent's objects) or ``"spawn"``.
    shared : mapping, optional
        Values the tasks read with :func:`shared` (set in this process for the pool's lifetime, so that
        forked workers and serial tasks see them alike).
    background : bool
        The workers run beside this process (:meth:`start`): a pool is made for a single worker too.
    """

    def __init__(self, workers: int, *, start_method: str = "fork", shared: Mapping[str, Any] | None = None,
                 background: bool = False) -> None:
        self.workers = int(workers)
        self.start_method = start_method
        self.background = background
        self._shared = dict(shared or {})
        self._saved: dict[str, Any] = {}
        self._pool: Any = None  # a multiprocessing Pool while open with workers > 1
        self._started: list[Any] = []  # the AsyncResults of start()

    def __enter__(self) -> ProcessPool:
        self._saved = {k: _SHARED[k] for k in self._shared if k in _SHARED}
        _SHARED.update(self._shared)
        if self.workers > (0 if self.background else 1):
            self._pool = multiprocessing.get_context(self.start_method).Pool(self.workers)
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if self._pool is not None:
            if exc_type is None and all(job.ready() for job in self._started):
                self._pool.close()  # every task is done: the workers exit on their own (and clean up)
            else:
                self._pool.terminate()  # an error, or work still running: stop the workers
            self._pool.join()
            self._pool = None
            self._started = []
        for key in self._shared:
            _SHARED.pop(key, None)
        _SHARED.update(self._saved)

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]:
        """``[fn(x) for x in items]``, in the workers when there are several."""
        if self._pool is None:
            return [fn(x) for x in items]
        return self._pool.map(fn, items)

    def imap_unordered(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> Iterator[Any]:
        """``fn(x)`` for every item, yielded as each finishes (in order when serial)."""
        if self._pool is None:
            return (fn(x) for x in items)
        return self._pool.imap_unordered(fn, items)

    def start(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Start ``fn(*args)`` in a worker and return at once (``multiprocessing`` ``AsyncResult``).

        Needs a pool made with ``background=True`` (and at least one worker), inside the with-block.
        """
        if self._pool is None:
            raise BatteryPredictorError("ProcessPool.start needs a background pool of at least one worker")
        job = self._pool.apply_async(fn, args)
        self._started.append(job)
        return job


def resident_mb(pid: int | None = None) -> float:
    """Resident memory (VmRSS) of process ``pid`` (default: this one) in MB; NaN where /proc is missing."""
    try:
        with open(f"/proc/{pid or os.getpid()}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")
