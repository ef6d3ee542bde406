"""The multi-threaded executor the nodes spin on, without rclpy 7.1's busy loop (rclpy issue #1452).

rclpy's :class:`~rclpy.executors.MultiThreadedExecutor` (Jazzy 7.1.x, fixed
upstream by rclpy PR #1547, not in the pinned wheels) hands a ready callback to
its thread pool and immediately asks the wait set for more work. Until a worker
has *started* that callback, the wait set yields it again at once, so the
spinning thread loops without blocking and holds the GIL while the worker that
should run the callback waits for it (measured cost: ``docs/findings.md``,
"Code notes"; ``benchmarks/executor_latency.py``).

:class:`StartedMultiThreadedExecutor` keeps everything else of the upstream
class and only waits, after handing a callback to the pool, until a worker has
started it. Callbacks still run in parallel (the route service is answered
while a runtime update is running); the spinning thread just never re-yields a
callback that is queued but not yet running.

Only rclpy versions before :data:`FIXED_IN` get the work-around (:data:`NEEDS_WORKAROUND`); from that
version on the class is upstream's executor unchanged. Remove this module, and spin the nodes on
rclpy's own :class:`~rclpy.executors.MultiThreadedExecutor`, once the oldest supported distribution
(Jazzy's 7.1.x today) ships rclpy >= 10.0.4 or a backport of the fix.
"""

from __future__ import annotations

import importlib.metadata
import re
import threading
from collections.abc import Callable

from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    MultiThreadedExecutor,
    ShutdownException,
    TimeoutException,
)

#: How often the spinning thread re-checks for shutdown while all workers are busy (s).
_START_POLL_S = 0.1

#: The first rclpy release whose MultiThreadedExecutor does not busy-loop (rclpy #1452, PR #1547).
FIXED_IN = (10, 0, 4)


def rclpy_version() -> tuple[int, ...] | None:
    """The installed rclpy's version as integers (``(7, 1, 5)``), or None when it cannot be read."""
    try:
        text = importlib.metadata.version("rclpy")
    except importlib.metadata.PackageNotFoundError:
        return None
    numbers = re.findall(r"\d+", text)[:3]
    return tuple(int(n) for n in numbers) or None


def needs_workaround(version: tuple[int, ...] | None) -> bool:
    """True for rclpy versions with the busy loop (before :data:`FIXED_IN`) and for an unknown one."""
    return version is None or version < FIXED_IN


#: Whether :class:`StartedMultiThreadedExecutor` replaces upstream's spin step in this environment.
NEEDS_WORKAROUND = needs_workaround(rclpy_version())


class StartedMultiThreadedExecutor(MultiThreadedExecutor):
    """A :class:`~rclpy.executors.MultiThreadedExecutor` that waits until each handed-over callback has started.

    Parameters
    ----------
    num_threads : int, optional
        Worker threads (rclpy's default when None: the CPUs this process may use).
    context : rclpy.context.Context, optional
        The context (default: the global one).
    """

    def _spin_once_impl(self, timeout_sec: float | None = None,
                        wait_condition: Callable[[], bool] = lambda: False) -> None:
        if not NEEDS_WORKAROUND:
            super()._spin_once_impl(timeout_sec, wait_condition)
            return
        try:
            handler, _entity, _node = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ExternalShutdownException, ShutdownException, TimeoutException, ConditionReachedException):
            return
        started = threading.Event()

        def run() -> None:
            started.set()
            handler()

        self._executor.submit(run)
        self._futures.append(handler)
        for future in self._futures[:]:
            if future.done():
                self._futures.remove(future)
                future.result()  # raise any exception of a callback, as upstream does
        # all workers busy: wait for one (nothing else could run anyway), but notice a shutdown
        while not started.wait(_START_POLL_S):
            if self._is_shutdown or not self._context.ok():
                return
