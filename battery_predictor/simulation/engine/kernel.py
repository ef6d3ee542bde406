"""The fused compiled kernel: modal recurrence, voltage at every step and the cut-off root, per set.

The cell voltage is PyBaMM's own expression (:attr:`LinearSpm.voltage_symbol`) turned into
scalar code: PyBaMM's code printer (``pybamm.to_python``) writes it as NumPy statements on the
rows of the voltage input array; the rows become scalar arguments and the NumPy functions
their ``math`` counterparts, and Numba compiles the result together with the stepping loop.
Expressions using anything else (interpolated data, constants arrays) have no compiled form;
:func:`fused_kernel` then returns None and the caller uses the NumPy path. A lumped thermal cell's
heat equation is printed the same way for the thermal recurrence (:func:`thermal_kernel`,
:mod:`~battery_predictor.simulation.engine.thermal`).

The fused kernel and the two-pass pieces (:class:`VoltageKernels`) are written with the printed
voltage to a module file per voltage and compiled with Numba's disk cache
(:mod:`~battery_predictor.simulation.engine.kernel_module`): a new process loads them in about a
second instead of compiling them (several seconds). The thermal kernel is compiled in memory
(no disk cache). Every compiled function releases the GIL.
"""

from __future__ import annotations

import math
import re
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from battery_predictor.simulation.engine.model import CURRENT, THERMAL_ROWS, VOLTAGE_ROWS, LinearSpm

#: A compiled Numba function (its argument types are fixed by Numba at the first call).
Kernel = Callable[..., Any]

#: NumPy functions of the printed voltage expression and their scalar replacements.
_SCALAR_FUNCTIONS = {
    "np.exp": "math.exp", "np.log": "math.log", "np.sqrt": "math.sqrt", "np.tanh": "math.tanh",
    "np.arcsinh": "math.asinh", "np.sinh": "math.sinh", "np.cosh": "math.cosh", "np.arctan": "math.atan",
    "np.abs": "abs", "np.minimum": "min", "np.maximum": "max",
}
_ROW = re.compile(r"y\[(\d+):(\d+)\]")
_NP_CALL = re.compile(r"np\.\w+")
_NAME = re.compile(r"\b(?:var_m?\d+|tmp\d+|y\d+)\b")
#: Compiled kernels by (printed voltage source, parallel).
_CACHE: dict[tuple, Any] = {}
#: Printed voltage source by model (printing takes milliseconds).
_SOURCES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Printed heat-equation source by model (thermal cells).
_RATE_SOURCES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Batches of at least this many sets run in the parallel kernel.
PARALLEL_MIN_SETS = 64


def _scalar_lines(symbol, n_rows: int) -> tuple[list[str], str] | None:
    """PyBaMM's printed NumPy statements of ``symbol`` as scalar statements on ``y0 .. y{n_rows-1}``.

    Returns (statements, name of the result), or None when the expression has no scalar form.
    """
    import pybamm

    constants, body = pybamm.to_python(symbol, debug=False)
    if constants:
        return None
    for call in set(_NP_CALL.findall(body)):
        if call not in _SCALAR_FUNCTIONS:
            return None
    for a, b in _ROW.findall(body):
        if int(b) != int(a) + 1 or int(a) >= n_rows:
            return None
    body = _ROW.sub(lambda m: f"y{m.group(1)}", body)
    for call, scalar in _SCALAR_FUNCTIONS.items():
        body = re.sub(re.escape(call) + r"\b", scalar, body)
    if "[" in body or "@" in body:
        return None
    lines = _canonical_names([line for line in body.splitlines() if line.strip()])
    return lines, lines[-1].split("=", 1)[0].strip()


def _canonical_names(lines: list[str]) -> list[str]:
    """PyBaMM's temporaries (``var_<symbol id>``, ids that differ from process to process) renamed ``tmp0, tmp1, ...``
    in order of appearance, so that one expression prints the same source in every process (the disk cache's key)."""
    names: dict[str, str] = {}

    def rename(match: re.Match) -> str:
        name = match.group(0)
        if name.startswith("y"):
            return name
        return names.setdefault(name, f"tmp{len(names)}")

    return [_NAME.sub(rename, line) for line in lines]


def scalar_voltage_source(model: LinearSpm) -> str | None:
    """Source of ``cell_voltage(y0, ..., y6)`` (scalar) from PyBaMM's printer, or None when unsupported."""
    printed = _scalar_lines(model.voltage_symbol, len(VOLTAGE_ROWS))
    if printed is None:
        return None
    lines, result = printed
    args = ", ".join(f"y{k}" for k in range(len(VOLTAGE_ROWS)))
    single = f"def cell_voltage({args}):\n    " + "\n    ".join(lines) + f"\n    return {result}\n"
    return single + "\n\n" + _pair_source(lines, result)


def scalar_rate_source(model: LinearSpm) -> str | None:
    """Source of ``cell_rate(y0, ..., y7)``: the lumped heat equation's ``dT/dt`` (K/s), or None."""
    if model.thermal is None:
        return None
    printed = _scalar_lines(model.thermal.rate_symbol, len(THERMAL_ROWS))
    if printed is None:
        return None
    lines, result = printed
    args = ", ".join(f"y{k}" for k in range(len(THERMAL_ROWS)))
    return f"def cell_rate({args}):\n    " + "\n    ".join(lines) + f"\n    return {result}\n"


def _pair_source(lines: list[str], result: str) -> str:
    """``cell_voltage_pair``: the voltage at one state under two currents, sharing what the current does not change.

    Statements that do not depend on the current row (open-circuit potentials, exchange-current
    densities) run once; those that do run twice, renamed.
    """
    current_row = f"y{VOLTAGE_ROWS.index(CURRENT)}"
    dependent = {current_row}
    shared, per_current = [], []
    for line in lines:
        target, expr = (part.strip() for part in line.split("=", 1))
        if set(_NAME.findall(expr)) & dependent:
            dependent.add(target)
            per_current.append((target, expr))
        else:
            shared.append(line)

    def renamed(suffix: str) -> list[str]:
        def sub(match: re.Match) -> str:
            name = match.group(0)
            return f"{name}_{suffix}" if name in dependent else name
        return [f"{target}_{suffix} = {_NAME.sub(sub, expr)}" for target, expr in per_current]

    args = ", ".join(f"y{k}" for k in range(len(VOLTAGE_ROWS)))
    args = args.replace(current_row, f"{current_row}_a, {current_row}_b")
    out_a = f"{result}_a" if result in dependent else result
    out_b = f"{result}_b" if result in dependent else result
    body = shared + renamed("a") + renamed("b")
    return f"def cell_voltage_pair({args}):\n    " + "\n    ".join(body) + f"\n    return {out_a}, {out_b}\n"


def fused_kernel(model: LinearSpm, *, parallel: bool = False):
    """The compiled run kernel for ``model``'s voltage, or None (no Numba, or no scalar form).

    ``parallel`` selects the variant that spreads the sets over the cores (its compilation
    takes several seconds, so single runs use the serial one). The kernel releases the GIL.
    """
    scalar = _scalar_kernels(model)
    if scalar is None:
        return None
    return scalar.run_parallel if parallel else scalar.run_serial


@dataclass(frozen=True)
class VoltageKernels:
    """A model's printed voltage compiled for the two-pass path (every function releases the GIL).

    Attributes
    ----------
    source : str
        The printed voltage source they were compiled from.
    voltage, voltage_pair : callable
        ``cell_voltage(y0, ..., y6)`` and ``cell_voltage_pair`` (:func:`scalar_voltage_source`), scalar.
    cutoff_root : callable
        ``cutoff_root(z, lam, drive, weights, h_s, current_a, v0, v1, temperature_k, eps_n, eps_p,
        height_m, cutoff_v, tol_s)``: :attr:`cutoff_roots` for one set (scalars and (n_modes,) rows).
    grid : callable
        ``grid(s_n, s_p, current_a, temperature_k, eps_n, eps_p, height_m, out)``: the cell voltage (V)
        into ``out`` (n_sets, n) at surface stoichiometries (n_sets, n), cell currents (A; (n_sets, n)
        or (1, n)) and per-set temperature (K), volume fractions and electrode height (m) ((n_sets,)).
    cutoff_roots : callable
        ``cutoff_roots(z, lam, drive, weights, h_s, current_a, v0, v1, temperature_k, eps_n, eps_p,
        height_m, cutoff_v, tol_s)``: time into the step (s, (n,)) at which the voltage meets
        ``cutoff_v`` for modal states ``z`` (n, n_modes) at step starts, steps of ``h_s`` s under
        ``current_a`` A with voltages ``v0`` above and ``v1`` below the cut-off at their ends: the
        fused kernel's Illinois regula falsi on the exact within-step solution, to ``tol_s``.
    within : callable
        ``within(z, lam, drive, weights, tau_s, current_a) -> (s_n, s_p)``: surface stoichiometries
        ``tau_s`` s into a step from modal state ``z`` (one set).
    surfaces_within : callable
        ``surfaces_within(checkpoints, lam, drive, weights, step, tau_s, current_a, out)``: surface
        stoichiometries (n, 2) into ``out``, ``tau_s[k]`` s into step ``step[k]`` from the state at that
        step's start (``checkpoints`` (n_steps + 1, n_modes), one set) under ``current_a[k]`` A.
    run_serial, run_parallel : callable
        The fused run kernel (:func:`fused_kernel`), sets one after the other or spread over the cores.
    """

    source: str
    voltage: Callable[..., Any]
    voltage_pair: Callable[..., Any]
    cutoff_root: Callable[..., Any]
    grid: Callable[..., Any]
    cutoff_roots: Callable[..., Any]
    within: Callable[..., Any]
    surfaces_within: Callable[..., Any]
    run_serial: Callable[..., Any]
    run_parallel: Callable[..., Any]


def voltage_kernels(model: LinearSpm) -> VoltageKernels | None:
    """The compiled voltage pieces of ``model`` (:class:`VoltageKernels`), or None (no Numba, no scalar form)."""
    return _scalar_kernels(model)


def _scalar_kernels(model: LinearSpm) -> VoltageKernels | None:
    try:
        import numba
    except ImportError:
        return None
    if model not in _SOURCES:
        _SOURCES[model] = scalar_voltage_source(model) or ""
    source = _SOURCES[model]
    if not source:
        return None
    key = ("scalar", source)
    if key not in _CACHE:
        _CACHE[key] = _compile_scalar(numba, source)
    return _CACHE[key]


def thermal_kernel(model: LinearSpm, *, parallel: bool = False):
    """The compiled thermal recurrence for ``model``'s heat equation, or None (no Numba, or no scalar form).

    When the voltage has a scalar form too the kernel also writes the voltage at every step start
    and end; otherwise it is given none (``voltage_source`` empty) and the voltage runs in NumPy.
    """
    try:
        import numba
    except ImportError:
        return None
    if model not in _RATE_SOURCES:
        _RATE_SOURCES[model] = scalar_rate_source(model) or ""
    source = _RATE_SOURCES[model]
    if not source:
        return None
    if model not in _SOURCES:
        _SOURCES[model] = scalar_voltage_source(model) or ""
    voltage_source = _SOURCES[model]
    key = ("thermal", source, voltage_source, bool(parallel))
    if key not in _CACHE:
        _CACHE[key] = compile_thermal_kernel(numba, source, voltage_source, bool(parallel))
    return _CACHE[key]


def forget_thermal_kernel(model: LinearSpm) -> None:
    """Use no compiled thermal recurrence for ``model`` from now on."""
    _RATE_SOURCES[model] = ""


def forget_kernel(model: LinearSpm) -> None:
    """Use no fused kernel for ``model`` from now on (its printed voltage did not compile)."""
    _SOURCES[model] = ""


def _compile_scalar(numba, source: str) -> VoltageKernels:
    """The printed voltage and the kernels built on it (:mod:`.kernel_module`; compiled, or loaded from Numba's
    disk cache, at their first call)."""
    from battery_predictor.simulation.engine.kernel_module import kernel_module

    module = kernel_module(numba, source)
    return VoltageKernels(source, module.cell_voltage, module.cell_voltage_pair, module.cutoff_root, module.grid,
                          module.cutoff_roots, module.within, module.surfaces_within, module.run_serial,
                          module.run_parallel)


def compile_thermal_kernel(numba, rate_source: str, voltage_source: str, parallel: bool):
    """The compiled recurrence for a heat equation printed as ``cell_rate(y0, ..., y7)`` (:func:`scalar_rate_source`).

    With a ``voltage_source`` (``cell_voltage`` and ``cell_voltage_pair``, above) the kernel writes
    the voltage at every step start and end; with an empty one it leaves them (``has_voltage`` False).
    """
    namespace: dict = {"math": math}
    exec(compile(rate_source, "<pybamm heat equation>", "exec"), namespace)  # noqa: S102 - printed by PyBaMM
    rate = numba.njit(fastmath=False, nogil=True)(namespace["cell_rate"])
    has_voltage = bool(voltage_source)
    if has_voltage:
        exec(compile(voltage_source, "<pybamm voltage>", "exec"), namespace)  # noqa: S102 - printed by PyBaMM
        voltage = numba.njit(fastmath=False, nogil=True)(namespace["cell_voltage"])
        voltage_pair = numba.njit(fastmath=False, nogil=True)(namespace["cell_voltage_pair"])
    else:
        @numba.njit(fastmath=False, nogil=True)
        def voltage(y0, y1, y2, y3, y4, y5, y6):  # pragma: no cover - compiled, never called
            return math.nan

        @numba.njit(fastmath=False, nogil=True)
        def voltage_pair(y0, y1, y2a, y2b, y3, y4, y5, y6):  # pragma: no cover - compiled, never called
            return math.nan, math.nan

    @numba.njit(parallel=parallel, fastmath=False, nogil=True)
    def kernel(lam, drive, z0, temperature0_k, ambient_k, eps_n, eps_p, height_m, heat_rate, duration_s, current_a,
               weights,
               n_neg, inv0, dinv, ln_factor, constant, stride, surfaces, temps, factors, states,
               z_end, start_v, end_v, cutoff_v):  # pragma: no cover - compiled
        n_sets, n_modes = z0.shape
        n_steps = duration_s.shape[0]
        n_grid = ln_factor.shape[1]
        for s in numba.prange(n_sets):
            z = z0[s].copy()
            decay = np.empty(n_modes)
            phid = np.empty(n_modes)
            t = temperature0_k[s]
            t_amb, en, ep, hh, f_rate = ambient_k[s], eps_n[s], eps_p[s], height_m[s], heat_rate[s]
            sn = 0.0
            sp = 0.0
            for j in range(n_modes):
                sn += weights[0, j] * z[j]
                sp += weights[1, j] * z[j]
            surfaces[s, 0, 0] = sn
            surfaces[s, 0, 1] = sp
            temps[s, 0] = t
            for j in range(n_modes):
                states[s, 0, j] = z[j]
            last_h = -1.0
            if has_voltage and n_steps > 0:
                start_v[s, 0] = voltage(sn, sp, current_a[0], t, en, ep, hh)
            # a voltage below the cut-off ends the set: what follows is NaN (first start voltage, end
            # voltage and boundary that are past the end; n_steps / n_steps + 1 when it runs to the end)
            nan_start, nan_end, nan_boundary = n_steps, n_steps, n_steps + 1
            for k in range(n_steps):
                h = duration_s[k]
                i = current_a[k]
                if has_voltage and not start_v[s, k] >= cutoff_v:
                    nan_start, nan_end, nan_boundary = k + 1, k, k + 1
                    break
                r0 = f_rate * rate(sn, sp, i, t, en, ep, hh, t_amb)
                g_n = 1.0
                g_p = 1.0
                if not constant:
                    x = (1.0 / (t + 0.5 * h * r0) - inv0) / dinv
                    jj = int(math.floor(x))
                    if jj < 0:
                        jj = 0
                    if jj > n_grid - 2:
                        jj = n_grid - 2
                    frac = x - jj
                    g_n = math.exp(ln_factor[0, jj] * (1.0 - frac) + ln_factor[0, jj + 1] * frac)
                    g_p = math.exp(ln_factor[1, jj] * (1.0 - frac) + ln_factor[1, jj + 1] * frac)
                factors[s, k, 0] = g_n
                factors[s, k, 1] = g_p
                if (not constant) or h != last_h:
                    for j in range(n_modes):
                        lj = lam[s, j] * (g_n if j < n_neg else g_p)
                        if lj == 0.0:
                            decay[j] = 1.0
                            phid[j] = h * drive[s, j]
                        else:
                            x = lj * h
                            decay[j] = math.exp(x)
                            phid[j] = math.expm1(x) / lj * drive[s, j]
                    last_h = h
                sn = 0.0
                sp = 0.0
                for j in range(n_modes):
                    z[j] = decay[j] * z[j] + phid[j] * i
                    sn += weights[0, j] * z[j]
                    sp += weights[1, j] * z[j]
                r1 = f_rate * rate(sn, sp, i, t + h * r0, en, ep, hh, t_amb)
                t = t + 0.5 * h * (r0 + r1)
                if has_voltage:  # the step's end and the next step's start share the state
                    if k + 1 < n_steps:
                        end_v[s, k], start_v[s, k + 1] = voltage_pair(sn, sp, i, current_a[k + 1], t, en, ep, hh)
                    else:
                        end_v[s, k] = voltage(sn, sp, i, t, en, ep, hh)
                surfaces[s, k + 1, 0] = sn
                surfaces[s, k + 1, 1] = sp
                temps[s, k + 1] = t
                if (k + 1) % stride == 0:
                    for j in range(n_modes):
                        states[s, (k + 1) // stride, j] = z[j]
                if has_voltage and not end_v[s, k] >= cutoff_v:
                    nan_start, nan_end, nan_boundary = k + 1, k + 1, k + 2
                    break
            for kk in range(nan_start, n_steps):
                start_v[s, kk] = math.nan
            for kk in range(nan_end, n_steps):
                end_v[s, kk] = math.nan
            for kk in range(nan_boundary, n_steps + 1):
                surfaces[s, kk, 0] = math.nan
                surfaces[s, kk, 1] = math.nan
                temps[s, kk] = math.nan
            for j in range(n_modes):
                z_end[s, j] = z[j]

    return kernel, has_voltage
