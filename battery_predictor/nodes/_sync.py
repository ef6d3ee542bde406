"""Progress probes that let an in-process replay run the nodes in lock step with the bag.

A replay that publishes ``/clock`` itself can wait, after every step, until the
nodes have handled everything due at that time (messages and timer callbacks),
so the outputs do not depend on how fast the machine is. These probes are
bookkeeping only; nodes run the same with or without a replay.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable

from rclpy.clock import Clock
from rclpy.timer import Timer


class TimerProbe:
    """Records when a timer's callback started and whether it is running.

    Parameters
    ----------
    clock : rclpy.clock.Clock
        The timer's clock (the node clock).
    """

    def __init__(self, clock: Clock) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self.timer: Timer | None = None
        self.last_start_ns = clock.now().nanoseconds
        self.running = False
        self.calls = 0

    def wrap(self, callback: Callable[[], None]) -> Callable[[], None]:
        """The callback to pass to ``create_timer`` (then set :attr:`timer`)."""

        @functools.wraps(callback)
        def probed() -> None:
            with self._lock:
                self.running = True
                self.last_start_ns = self._clock.now().nanoseconds
                self.calls += 1
            try:
                callback()
            finally:
                with self._lock:
                    self.running = False

        return probed

    def idle(self, now_ns: int) -> bool:
        """True when nothing of this timer is due or in flight at the (frozen) clock time ``now_ns``.

        The executor marks a timer as called (``time_since_last_call() == 0`` on
        a frozen clock) before it runs the Python callback; that gap counts as
        busy until the callback recorded its start at ``now_ns`` and finished.
        """
        timer = self.timer
        if timer is None or timer.is_canceled():
            return True
        try:
            until_next = timer.time_until_next_call()
            since_last = timer.time_since_last_call()
        except Exception:  # noqa: BLE001 - a destroyed timer is idle
            return True
        with self._lock:
            if self.running:
                return False
            if until_next is not None and until_next <= 0:
                return False
            return since_last > 0 or self.last_start_ns >= now_ns
