"""Route answers ahead of a concurrent runtime update of the same pack model.

A route answer (``can_accept_route``) takes a few milliseconds of Python; a runtime update takes
tens to hundreds of milliseconds of model runs. When both run in one process (the node answers
the service while its timer updates the runtime), the two threads share the interpreter lock,
and the route answer waits for it behind the update (CPython hands the lock over only every
switch interval, 5 ms, while the other thread computes). :class:`RoutePriority` counts the route
answers in progress; :class:`YieldingRunner` is the pack model as the runtime update sees it:
before each model run it waits until no route answer is in progress, so an update pauses
between its runs (not inside one) while a route is answered. Nothing else changes: the same
runs, in the same order, with the same results.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

#: Longest a runtime update's run waits for route answers (s); a safety bound, never reached in practice.
MAX_WAIT_S = 2.0


class RoutePriority:
    """How many route answers are in progress; background work waits for them (see module docstring).

    Parameters
    ----------
    max_wait_s : float
        Longest a waiting run waits (s), whatever the answers do.
    """

    def __init__(self, max_wait_s: float = MAX_WAIT_S) -> None:
        self._condition = threading.Condition()
        self._answering = 0
        self.max_wait_s = float(max_wait_s)

    @contextmanager
    def answering(self) -> Iterator[None]:
        """Mark a route answer in progress for the duration of the ``with`` block."""
        with self._condition:
            self._answering += 1
        try:
            yield
        finally:
            with self._condition:
                self._answering -= 1
                if self._answering == 0:
                    self._condition.notify_all()

    def wait_for_answers(self) -> None:
        """Return once no route answer is in progress (at once when none is), at most after ``max_wait_s``."""
        if self._answering == 0:  # the common case, without the lock
            return
        with self._condition:
            self._condition.wait_for(lambda: self._answering == 0, timeout=self.max_wait_s)


class YieldingRunner:
    """A pack model whose runs first wait for route answers in progress (:meth:`RoutePriority.wait_for_answers`).

    Everything else (``soc_bounds``, ``capacity_ah``, ``soc_of``, ...) is the wrapped model's; it compares and
    hashes as the wrapped model, so caches keyed by the model are shared.

    Parameters
    ----------
    runner : PackRunner or EnginePack
        The pack model.
    priority : RoutePriority
        The route answers to wait for.
    """

    def __init__(self, runner: Any, priority: RoutePriority) -> None:
        self._runner = runner
        self._priority = priority

    def run(self, *args: Any, **kwargs: Any) -> Any:
        """The wrapped model's ``run``, after the route answers in progress."""
        self._priority.wait_for_answers()
        return self._runner.run(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._runner, name)

    def __eq__(self, other: object) -> bool:
        return self._runner == (other._runner if isinstance(other, YieldingRunner) else other)

    def __hash__(self) -> int:
        return hash(self._runner)
