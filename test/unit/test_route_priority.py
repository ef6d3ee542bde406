"""Route answers ahead of a concurrent runtime update (prediction/priority.py)."""

from __future__ import annotations

import threading
import time

from battery_predictor.prediction.priority import RoutePriority, YieldingRunner


class _Runner:
    soc_bounds = (0.0, 1.0)

    def __init__(self) -> None:
        self.runs: list[float] = []

    def run(self, start, segments, temperature_k):
        self.runs.append(time.perf_counter())
        return start


def test_runs_wait_while_a_route_is_answered_and_pass_at_once_otherwise():
    priority, runner = RoutePriority(), _Runner()
    background = YieldingRunner(runner, priority)
    assert background.run(0.5, [], 298.15) == 0.5 and len(runner.runs) == 1
    released = []
    with priority.answering():
        worker = threading.Thread(target=lambda: background.run(0.4, [], 298.15))
        worker.start()
        time.sleep(0.2)
        assert len(runner.runs) == 1  # waiting for the answer
        released.append(time.perf_counter())
    worker.join(2.0)
    assert len(runner.runs) == 2 and runner.runs[1] >= released[0]


def test_a_wait_is_bounded_and_the_wrapper_is_the_model_for_caches():
    priority, runner = RoutePriority(max_wait_s=0.05), _Runner()
    background = YieldingRunner(runner, priority)
    with priority.answering():
        t0 = time.perf_counter()
        background.run(0.5, [], 298.15)
        assert time.perf_counter() - t0 < 1.0
    assert background.soc_bounds == (0.0, 1.0)
    assert background == runner and hash(background) == hash(runner)
    assert {background: 1}[runner] == 1
