"""The engine's kernels as files Numba caches on disk (simulation/engine/kernel_module.py)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from battery_predictor.simulation.engine.kernel import _canonical_names
from battery_predictor.simulation.engine.kernel_module import CACHE_ENV, MAX_FILES, _prune, kernel_module

#: A stand-in for a printed voltage (the real one takes a PyBaMM extraction).
SOURCE = '''def cell_voltage(y0, y1, y2, y3, y4, y5, y6):
    tmp0 = 4.2 - y0 + 0.5 * y1 - 0.01 * y2
    return tmp0


def cell_voltage_pair(y0, y1, y2_a, y2_b, y3, y4, y5, y6):
    tmp0_a = 4.2 - y0 + 0.5 * y1 - 0.01 * y2_a
    tmp0_b = 4.2 - y0 + 0.5 * y1 - 0.01 * y2_b
    return tmp0_a, tmp0_b
'''

_SECOND_PROCESS = """
import numba, numpy as np
from battery_predictor.simulation.engine.kernel_module import kernel_module
module = kernel_module(numba, SOURCE_REPR)
out = np.empty((1, 3))
module.grid(np.full((1, 3), 0.5), np.full((1, 3), 0.5), np.ones((1, 3)), *(np.ones(1) for _ in range(4)), out)
print(sum(module.grid.stats.cache_hits.values()), sum(module.grid.stats.cache_misses.values()))
"""


def test_printed_temporaries_get_names_independent_of_pybamm_symbol_ids():
    a = _canonical_names(["var_m81 = y3", "var_6 = 2.0 * var_m81", "var_m2 = var_6 / y2"])
    b = _canonical_names(["var_m5 = y3", "var_77 = 2.0 * var_m5", "var_9 = var_77 / y2"])
    assert a == b == ["tmp0 = y3", "tmp1 = 2.0 * tmp0", "tmp2 = tmp1 / y2"]


def test_a_second_process_loads_the_compiled_kernels_from_the_disk_cache(tmp_path, monkeypatch):
    numba = pytest.importorskip("numba")
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    module = kernel_module(numba, SOURCE)
    assert module is kernel_module(numba, SOURCE)  # one module per source in a process
    out = np.empty((1, 3))
    module.grid(np.full((1, 3), 0.5), np.full((1, 3), 0.5), np.ones((1, 3)), *(np.ones(1) for _ in range(4)), out)
    np.testing.assert_allclose(out, 4.2 - 0.5 + 0.25 - 0.01)
    assert len(list(tmp_path.glob("engine_kernel_*.py"))) == 1
    env = dict(os.environ, **{CACHE_ENV: str(tmp_path)})
    proc = subprocess.run([sys.executable, "-c", _SECOND_PROCESS.replace("SOURCE_REPR", repr(SOURCE))], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    hits, misses = (int(x) for x in proc.stdout.split())
    assert hits == 1 and misses == 0


def test_old_kernel_files_are_pruned_with_their_cached_code(tmp_path):
    (tmp_path / "__pycache__").mkdir()
    for k in range(MAX_FILES + 3):
        (tmp_path / f"engine_kernel_{k:03d}.py").write_text("")
        (tmp_path / "__pycache__" / f"engine_kernel_{k:03d}.grid-1.py311.nbi").write_text("")
        os.utime(tmp_path / f"engine_kernel_{k:03d}.py", (k, k))
    _prune(tmp_path)
    kept = sorted(f.stem for f in tmp_path.glob("engine_kernel_*.py"))
    assert len(kept) == MAX_FILES - 1 and kept[0] == f"engine_kernel_{4:03d}"
    assert len(list((tmp_path / "__pycache__").glob("*.nbi"))) == MAX_FILES - 1


def test_a_kernel_file_another_process_published_first_is_never_rewritten(tmp_path):
    import os

    from battery_predictor.simulation.engine.kernel_module import _publish

    path = tmp_path / "engine_kernel_x.py"
    path.write_text("first\n")
    os.utime(path, (1_000_000_000, 1_000_000_000))
    tmp = tmp_path / "late.tmp"
    tmp.write_text("second\n")
    _publish(tmp, path)
    assert path.read_text() == "first\n" and path.stat().st_mtime == 1_000_000_000  # Numba's cache key kept
    assert not tmp.exists()
    fresh = tmp_path / "fresh.tmp"
    fresh.write_text("new\n")
    _publish(fresh, tmp_path / "engine_kernel_y.py")
    assert (tmp_path / "engine_kernel_y.py").read_text() == "new\n" and not fresh.exists()


def test_kernel_files_written_within_the_hour_are_never_pruned(tmp_path):
    import time

    from battery_predictor.simulation.engine.kernel_module import PRUNE_MIN_AGE_S

    now = time.time()
    for k in range(MAX_FILES + 3):  # more than the cache keeps, all written recently (e.g. by parallel workers)
        path = tmp_path / f"engine_kernel_{k:03d}.py"
        path.write_text("")
        os.utime(path, (now - 0.5 * PRUNE_MIN_AGE_S - k, now - 0.5 * PRUNE_MIN_AGE_S - k))
    _prune(tmp_path)
    assert len(list(tmp_path.glob("engine_kernel_*.py"))) == MAX_FILES + 3  # another process may import any of them
