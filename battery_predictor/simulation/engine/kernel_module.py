"""The fused kernel and the two-pass pieces as a module file per printed voltage, so Numba caches them on disk.

The compiled functions of :mod:`~battery_predictor.simulation.engine.kernel` are built on the cell
voltage PyBaMM prints for each model, so their source exists only at run time. Numba caches
machine code only for functions defined in a file (it keys the cache on the file's path and
stamp), so the printed voltage and the kernels' source (:data:`KERNELS_SOURCE`) are written to a
file named by a hash of both (never rewritten; a changed voltage or kernel is another file) in
:func:`cache_directory` and imported from there with ``cache=True``: a second process (a CLI
call, a node restart) loads the compiled kernels instead of compiling them again (seconds). Where
no directory is writable the same source is executed in memory and compiled without the cache.
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType, SimpleNamespace

#: Environment variable naming the directory for the kernel files (default: the user cache directory).
CACHE_ENV = "BATTERY_PREDICTOR_KERNEL_CACHE"

#: Kernel files kept (one per printed voltage, about 0.5 MB with their cached code); the oldest go first.
MAX_FILES = 64

#: The kernels on ``cell_voltage`` / ``cell_voltage_pair`` (printed above them in the module file).
KERNELS_SOURCE = '''
_jit = numba.njit(cache=_CACHE, fastmath=False, nogil=True, error_model="numpy")
cell_voltage = _jit(cell_voltage)
cell_voltage_pair = _jit(cell_voltage_pair)


@_jit
def within(z, lam, drive, weights, tau, current):
    sn = 0.0
    sp = 0.0
    for j in range(z.shape[0]):
        x = lam[j] * tau
        if lam[j] == 0.0:
            zj = z[j] + tau * drive[j] * current
        else:
            zj = math.exp(x) * z[j] + math.expm1(x) / lam[j] * drive[j] * current
        sn += weights[0, j] * zj
        sp += weights[1, j] * zj
    return sn, sp


@_jit
def cutoff_root(z, lam, drive, weights, h, i, v0, v1, temp, en, ep, hh, cutoff_v, tol_s):
    # Illinois regula falsi on the exact within-step solution
    lo, hi, f_lo, f_hi, side = 0.0, h, v0 - cutoff_v, v1 - cutoff_v, 0
    for _ in range(100):
        if hi - lo <= tol_s:
            break
        mid = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not (lo < mid < hi):
            mid = 0.5 * (lo + hi)
        a, b = within(z, lam, drive, weights, mid, i)
        f_mid = cell_voltage(a, b, i, temp, en, ep, hh) - cutoff_v
        if f_mid == 0.0:
            lo = mid
            hi = mid
            break
        if f_mid < 0.0:
            hi, f_hi = mid, f_mid
            if side == -1:
                f_lo *= 0.5
            side = -1
        else:
            lo, f_lo = mid, f_mid
            if side == 1:
                f_hi *= 0.5
            side = 1
    return 0.5 * (lo + hi)


@_jit
def cutoff_roots(z, lam, drive, weights, h, i, v0, v1, temp, en, ep, hh, cutoff_v, tol_s):
    out = np.empty(z.shape[0])
    for s in range(z.shape[0]):
        out[s] = cutoff_root(z[s], lam[s], drive[s], weights, h[s], i[s], v0[s], v1[s], temp[s], en[s], ep[s],
                             hh[s], cutoff_v, tol_s)
    return out


@_jit
def grid(s_n, s_p, current, temp, en, ep, hh, out):
    rows = current.shape[0]
    for s in range(s_n.shape[0]):
        r = s if rows > 1 else 0
        for k in range(s_n.shape[1]):
            out[s, k] = cell_voltage(s_n[s, k], s_p[s, k], current[r, k], temp[s], en[s], ep[s], hh[s])


@_jit
def surfaces_within(checkpoints, lam, drive, weights, step, tau, current, out):
    for k in range(step.shape[0]):
        out[k, 0], out[k, 1] = within(checkpoints[step[k]], lam, drive, weights, tau[k], current[k])
'''

#: The run kernel (one set per ``prange`` iteration), once serial (``run_serial``) and once parallel.
RUN_SOURCE = '''

@numba.njit(cache=_CACHE, parallel=_PARALLEL, fastmath=False, nogil=True)
def _NAME(lam, drive, z0, duration_s, current_a, weights, temperature_k, eps_n, eps_p, height_m, cutoff_v,
          tol_s, start_v, end_v, end_time, cutoff_step, at_start, z_end):
    n_sets, n_modes = z0.shape
    n_steps = duration_s.shape[0]
    for s in numba.prange(n_sets):
        z = z0[s].copy()
        decay = np.empty(n_modes)
        phid = np.empty(n_modes)
        last_h = -1.0
        t = 0.0
        cutoff_step[s] = n_steps
        at_start[s] = False
        end_time[s] = 0.0
        temp, en, ep, hh = temperature_k[s], eps_n[s], eps_p[s], height_m[s]
        sn = 0.0
        sp = 0.0
        for j in range(n_modes):
            sn += weights[0, j] * z[j]
            sp += weights[1, j] * z[j]
        v_next = cell_voltage(sn, sp, current_a[0], temp, en, ep, hh)
        for k in range(n_steps):
            h = duration_s[k]
            i = current_a[k]
            v0 = v_next
            start_v[s, k] = v0
            if not v0 >= cutoff_v:
                cutoff_step[s] = k
                at_start[s] = True
                end_time[s] = t
                break
            if h != last_h:
                for j in range(n_modes):
                    x = lam[s, j] * h
                    decay[j] = math.exp(x)
                    if lam[s, j] == 0.0:
                        phid[j] = h * drive[s, j]
                    else:
                        phid[j] = math.expm1(x) / lam[s, j] * drive[s, j]
                last_h = h
            sn = 0.0
            sp = 0.0
            for j in range(n_modes):
                zj = decay[j] * z[j] + phid[j] * i
                sn += weights[0, j] * zj
                sp += weights[1, j] * zj
            if k + 1 < n_steps:  # the step's end and the next step's start share the state
                v1, v_next = cell_voltage_pair(sn, sp, i, current_a[k + 1], temp, en, ep, hh)
            else:
                v1 = cell_voltage(sn, sp, i, temp, en, ep, hh)
            if not v1 >= cutoff_v:  # root inside the step
                tau = cutoff_root(z, lam[s], drive[s], weights, h, i, v0, v1, temp, en, ep, hh, cutoff_v, tol_s)
                cutoff_step[s] = k
                end_time[s] = t + tau
                for j in range(n_modes):
                    x = lam[s, j] * tau
                    if lam[s, j] == 0.0:
                        z[j] = z[j] + tau * drive[s, j] * i
                    else:
                        z[j] = math.exp(x) * z[j] + math.expm1(x) / lam[s, j] * drive[s, j] * i
                break
            end_v[s, k] = v1
            for j in range(n_modes):
                z[j] = decay[j] * z[j] + phid[j] * i
            t += h
        if cutoff_step[s] == n_steps:
            end_time[s] = t
        for j in range(n_modes):
            z_end[s, j] = z[j]
'''


def module_source(voltage_source: str, cache: bool) -> str:
    """The module text: imports, the printed voltage (:func:`~.kernel.scalar_voltage_source`), the kernels."""
    runs = "".join(RUN_SOURCE.replace("_NAME", name).replace("_PARALLEL", str(parallel))
                   for name, parallel in (("run_serial", False), ("run_parallel", True)))
    header = f"import math\n\nimport numba\nimport numpy as np\n\n_CACHE = {cache}\n\n\n"
    return header + voltage_source + "\n" + KERNELS_SOURCE + runs


def cache_directory() -> Path | None:
    """Where the kernel files go (:data:`CACHE_ENV`, else ``$XDG_CACHE_HOME`` or ``~/.cache``), None when not writable."""
    configured = os.environ.get(CACHE_ENV)
    base = Path(configured) if configured else \
        Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "battery_predictor" / "engine_kernels"
    try:
        base.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return base if os.access(base, os.W_OK) else None


#: Kernel files younger than this (s) are never pruned: another process may be about to import one.
PRUNE_MIN_AGE_S = 3600.0


def _prune(directory: Path, keep: int = MAX_FILES - 1) -> None:
    """Delete all but the ``keep`` newest kernel files of ``directory`` and their cached code (files
    younger than :data:`PRUNE_MIN_AGE_S` stay)."""
    stamped = []
    for f in directory.glob("engine_kernel_*.py"):
        try:
            stamped.append((f.stat().st_mtime, f))
        except OSError:  # pruned by another process meanwhile
            continue
    stamped.sort(reverse=True)
    now = time.time()
    for mtime, old in stamped[keep:]:
        if now - mtime < PRUNE_MIN_AGE_S:
            continue
        for cached in [old, *(directory / "__pycache__").glob(f"{old.stem}.*")]:
            try:
                cached.unlink()
            except OSError:  # another process pruned it first
                pass


def _publish(tmp: Path, path: Path) -> None:
    """Move the written ``tmp`` to ``path`` unless another process published it first (never overwrite:
    a rewritten file gets a new stamp, which invalidates every process's compiled cache)."""
    try:
        os.link(tmp, path)  # atomic, and fails when the file exists
    except FileExistsError:
        pass
    except OSError:  # no hard links on this file system
        if not path.exists():
            os.replace(tmp, path)
            return
    tmp.unlink(missing_ok=True)


def kernel_module(numba, voltage_source: str) -> ModuleType | SimpleNamespace:
    """The compiled functions of :func:`module_source` for a printed voltage, cached on disk where possible.

    Returns a module (or, without a writable directory, a namespace) with ``cell_voltage``,
    ``cell_voltage_pair``, ``within``, ``cutoff_root``, ``cutoff_roots``, ``grid``, ``surfaces_within``,
    ``run_serial`` and ``run_parallel`` (Numba dispatchers; compiled, or loaded, at their first call).
    """
    directory = cache_directory()
    if directory is None:
        namespace: dict = {"math": math}
        exec(compile(module_source(voltage_source, False), "<pybamm voltage>", "exec"), namespace)  # noqa: S102
        return SimpleNamespace(**namespace)
    text = module_source(voltage_source, True)
    digest = hashlib.sha256(f"{numba.__version__}\n{text}".encode()).hexdigest()[:20]
    path = directory / f"engine_kernel_{digest}.py"
    if not path.exists():  # written once, whole (the cache is keyed on the file's stamp: never rewrite it)
        _prune(directory)
        with tempfile.NamedTemporaryFile("w", dir=directory, suffix=".tmp", delete=False) as tmp:
            tmp.write(text)
        _publish(Path(tmp.name), path)
    spec = importlib.util.spec_from_file_location(f"battery_predictor_engine_kernel_{digest}", path)
    assert spec is not None and spec.loader is not None  # a .py file we just wrote
    if spec.name in sys.modules:
        return sys.modules[spec.name]
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # Numba's cached code refers to its module by name
    spec.loader.exec_module(module)
    return module
