"""Fixtures shared by every test directory (the shipped Temi params, a synthetic Temi discharge).

``make test`` runs the suite in worker processes (pytest-xdist, ``-n auto --dist loadfile``): a
session fixture is made once per worker, so the expensive ones are made once per run and shared
through a file under the run's temporary directory (:func:`_once_per_run`).
"""

from __future__ import annotations

import fcntl
import importlib.util
import os
import pickle
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

# Under pytest-xdist every worker process would start one Numba thread per core for the engine's parallel
# kernels: share the cores out instead (set before anything imports Numba; an explicit setting wins).
if os.environ.get("PYTEST_XDIST_WORKER_COUNT"):
    os.environ.setdefault("NUMBA_NUM_THREADS", str(max(1, len(os.sched_getaffinity(0))
                                                       // int(os.environ["PYTEST_XDIST_WORKER_COUNT"]))))

from battery_predictor.params import load_params  # noqa: E402  (after the thread setting)
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[1]

#: Parameters the synthetic "truth" pack differs in from the shipped Temi params.
SYNTHETIC_TRUTH = {
    "Electrode height [m]": 0.80,
    "Negative electrode active material volume fraction": 0.66,
    "r_c_ohm": 0.06,
}


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--extended", action="store_true",
                     help="also run the tests marked extended (held-out checks too slow for make test)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--extended"):
        return
    skip = pytest.mark.skip(reason="extended check: run with --extended (make test-extended)")
    for item in items:
        if "extended" in item.keywords:
            item.add_marker(skip)


def _synthesize(params, seed: int) -> Recording:
    """A liionpack discharge of the Temi pack under a (3x heavier) usage profile, 5 s samples + noise."""
    from battery_predictor.profiles.temi import generate_usage_profile
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.liionpack_sim import LiionpackSimulator

    profile = generate_usage_profile(seed=seed, max_duration_s=4 * 3600)
    load = StepLoad.from_profile(profile).scale_current(3.0).resample(10.0)
    res = LiionpackSimulator(period_s=10.0).simulate(params, SimulationRequest(load=load))
    rng = np.random.default_rng(seed)
    v = np.round(res.pack_voltage_v + rng.normal(0.0, 0.003, res.time_s.size), 2)
    return Recording(time_s=res.time_s, voltage_v=v, current_a=np.round(res.pack_current_a, 1),
                     temperature_k=np.full(res.time_s.size, 298.15), source=f"synthetic-{seed}")


def _once_per_run(tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[], Any]) -> Any:
    """``make()``, computed once per test run and shared by the xdist workers (in one process: just ``make()``).

    The first worker to ask computes it under an exclusive lock and leaves it pickled in the directory all
    workers' temporary directories share; the others wait on the lock and load it.
    """
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        return make()
    shared = tmp_path_factory.getbasetemp().parent
    path = shared / f"{name}.pickle"
    with open(shared / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if path.is_file():
            return pickle.loads(path.read_bytes())
        value = make()
        partial = path.with_suffix(".partial")
        partial.write_bytes(pickle.dumps(value))
        os.replace(partial, path)
        return value


@pytest.fixture(scope="session")
def process_workers_args() -> list[str]:
    """``--workers N`` for a CLI that starts a process pool of its own (diagnose): the CPUs shared out among the
    xdist workers, so that two workers running diagnoses do not start twice as many processes as there are
    cores; empty (the command's default) when the tests run in one process."""
    count = os.environ.get("PYTEST_XDIST_WORKER_COUNT")
    if count is None:
        return []
    return ["--workers", str(max(1, len(os.sched_getaffinity(0)) // int(count)))]


@pytest.fixture(scope="session")
def temi_params():
    return load_params(REPO / "params" / "temi.yaml")


@pytest.fixture(scope="session")
def synthetic_temi(temi_params, tmp_path_factory):
    """(truth values, truth params, training recording, held-out recording) made by liionpack."""
    truth = temi_params.with_values(SYNTHETIC_TRUTH)
    train, held_out = _once_per_run(tmp_path_factory, "synthetic_temi",
                                    lambda: (_synthesize(truth, 11), _synthesize(truth, 12)))
    return dict(SYNTHETIC_TRUTH), truth, train, held_out


@pytest.fixture(scope="session")
def ranger_params():
    """The shipped Ranger Mini params."""
    return load_params(REPO / "params" / "ranger_mini.yaml")


@pytest.fixture(scope="session")
def longest_route_segments():
    """[(duration_s, pack current A), ...] of the longest route at 80 kg (mean currents), then 60 s standstill."""
    from battery_predictor.profiles.ranger import longest_route, route_profile

    profile = route_profile(longest_route(80.0), mode="mean")
    return list(zip(profile.duration_s, profile.current_a)) + [(60.0, 1.70)]


def load_script(path: Path) -> ModuleType:
    """A script of the repository that is not part of the package (``benchmarks/``, ``docs/``), imported as a module."""
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None, path
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def repo_script() -> Callable[[str], ModuleType]:
    """``repo_script("benchmarks/diagnosis_rescore.py")``: :func:`load_script` of a path relative to the repository."""
    return lambda relative: load_script(REPO / relative)
