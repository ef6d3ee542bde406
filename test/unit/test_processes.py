"""The one process pool (battery_predictor.processes): serial, forked with shared values, in the background."""

from __future__ import annotations

import os

import pytest

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.processes import ProcessPool, resident_mb, shared


def _scaled(x: int) -> tuple[int, int]:
    return x * shared("factor"), os.getpid()


def test_serial_pool_runs_in_this_process_in_order():
    with ProcessPool(1, shared={"factor": 3}) as pool:
        out = pool.map(_scaled, [1, 2, 3])
        assert list(pool.imap_unordered(_scaled, [4, 5])) == [(12, os.getpid()), (15, os.getpid())]
    assert out == [(3, os.getpid()), (6, os.getpid()), (9, os.getpid())]


def test_forked_workers_see_the_shared_values_without_pickling_them():
    unpicklable = lambda: 2  # noqa: E731 - a lambda cannot be pickled: the workers inherit it by the fork
    with ProcessPool(2, shared={"factor": unpicklable()}) as pool:
        out = pool.map(_scaled, range(6))
        unordered = sorted(v for v, _ in pool.imap_unordered(_scaled, range(4)))
    assert [v for v, _ in out] == [0, 2, 4, 6, 8, 10]
    assert all(pid != os.getpid() for _, pid in out)
    assert unordered == [0, 2, 4, 6]


def test_shared_values_are_restored_when_pools_nest():
    with ProcessPool(1, shared={"factor": 2}):
        with ProcessPool(1, shared={"factor": 5}):
            assert shared("factor") == 5
        assert shared("factor") == 2
    with pytest.raises(KeyError):
        shared("factor")


def test_a_background_pool_starts_one_worker_beside_this_process():
    with ProcessPool(1, shared={"factor": 7}, background=True) as pool:
        job = pool.start(_scaled, 6)
        value, pid = job.get(timeout=60)
    assert value == 42 and pid != os.getpid()
    with ProcessPool(1) as pool, pytest.raises(BatteryPredictorError):
        pool.start(_scaled, 1)


def test_resident_memory_of_this_process():
    assert 10.0 < resident_mb() < 100_000.0


def test_an_error_in_the_block_stops_the_workers_and_restores_the_shared_values():
    with pytest.raises(ValueError), ProcessPool(2, shared={"factor": 1}) as pool:
        pool.map(_scaled, [1, 2])
        raise ValueError("stop")
    assert pool._pool is None
    with pytest.raises(KeyError):
        shared("factor")
