"""The ``hysteresis`` extension on the engine: PyBaMM's one-state (Axen) OCP hysteresis, stepped exactly.

In the SPM the positive particles' interfacial current is uniform, so PyBaMM's hysteresis ODE of the
positive electrode (option ``{"open-circuit potential": ("single", "Axen")}`` with the lithiation /
delithiation OCPs the extension makes, OCP -/+ the half-width ``M``) is
``dh/dt = K |I| / Q_p (s - h)``, ``s = -sign(I)`` (with the extension's relaxation rate ``r`` not 0,
``- r h`` is added: the state relaxes towards 0 at rest), and the cell voltage is the hysteresis-free SPM's plus
``M h``. Neither depends on the particles, so the engine runs the cell without the option (its
extraction stays linear) and adds ``M h`` with ``h`` stepped exactly on the piecewise-constant current
(:func:`~battery_predictor.simulation.extensions.hysteresis_states`, the equations' one source).

The cut-off is located on the total voltage: the run goes on until the hysteresis-free voltage is below
the cut-off minus ``M`` (``|h| <= 1``, so the total is below the cut-off by then), and the first step
whose start or end total voltage is below the cut-off holds the end; inside a step the root is found on
the exact within-step solution of both (Illinois regula falsi), as the engine does without hysteresis.
Lumped thermal cells are not covered (the simulator falls back visibly).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, replace

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.engine.modal import ModalSystem, states_at, step_coefficients
from battery_predictor.simulation.engine.model import LinearSpm
from battery_predictor.simulation.engine.run import (
    CUTOFF_TIME_TOL_S,
    CellRuns,
    ParameterSets,
    run_cells,
    voltages_at_times,
)
from battery_predictor.simulation.extensions import hysteresis_states, hysteresis_step

#: Models with their cut-off moved down by the half-width, by (model, half-width) (printing a kernel's
#: voltage source is cached per model object).
_SHIFTED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_MAX_ROOT_ITERATIONS = 200


@dataclass(frozen=True)
class Hysteresis:
    """The extension's values for one run.

    Attributes
    ----------
    half_width_v : float
        ``M`` (V): the cell voltage is the hysteresis-free one plus ``M h``.
    rate_per_c : float
        ``K / Q_p`` (1/C).
    initial_state : float
        ``h`` at the start (-1 discharge branch .. +1 charge branch).
    relax_per_s : float
        Relaxation rate of ``h`` towards 0 (1/s; 0: PyBaMM's Axen model).
    """

    half_width_v: float
    rate_per_c: float
    initial_state: float
    relax_per_s: float = 0.0


@dataclass(frozen=True)
class HysteresisRun:
    """A cell run with the hysteresis voltage.

    Attributes
    ----------
    time_s : numpy.ndarray
        Report times kept (before the end).
    cell_voltage_v : numpy.ndarray
        Cell voltage (V) at those times, hysteresis included.
    hysteresis_state : numpy.ndarray
        ``h`` at those times.
    end_time_s : float
        When the run ended (s): at the cut-off, else at the end of the steps.
    reached_cutoff : bool
        True when the cell reached its lower cut-off.
    final_state : float
        ``h`` at ``end_time_s``.
    backend : str
        The engine path that ran.
    """

    time_s: np.ndarray
    cell_voltage_v: np.ndarray
    hysteresis_state: np.ndarray
    end_time_s: float
    reached_cutoff: bool
    final_state: float
    backend: str


def _shifted(model: LinearSpm, half_width_v: float) -> LinearSpm:
    per_model = _SHIFTED.setdefault(model, {})
    if half_width_v not in per_model:
        if len(per_model) > 32:
            per_model.clear()
        per_model[half_width_v] = replace(model, lower_cutoff_v=model.lower_cutoff_v - half_width_v)
    return per_model[half_width_v]


def states_at_times(start_s: np.ndarray, boundary_states: np.ndarray, duration_s: np.ndarray,
                    current_a: np.ndarray, rate_per_c: float, time_s: np.ndarray, relax_per_s: float = 0.0) -> np.ndarray:
    """``h`` at ``time_s`` from its values at the step boundaries (exact inside each step)."""
    step = np.clip(np.searchsorted(start_s, time_s, side="right") - 1, 0, duration_s.size - 1)
    tau = np.minimum(time_s - start_s[step], duration_s[step])
    return hysteresis_step(boundary_states[step], current_a[step], tau, rate_per_c, relax_per_s)


def run_cell(model: LinearSpm, modal: ModalSystem, duration_s: np.ndarray, current_a: np.ndarray, *,
             c_n0_mol_m3: float, c_p0_mol_m3: float, temperature_k: float, sets: ParameterSets, backend: str,
             hysteresis: Hysteresis, time_s: np.ndarray) -> HysteresisRun:
    """One isothermal cell through constant-current steps with the hysteresis voltage, to the cut-off.

    Parameters
    ----------
    model, modal : LinearSpm, ModalSystem
        The hysteresis-free cell (extracted without the option) and its modal form.
    duration_s, current_a : numpy.ndarray
        Step lengths (s) and cell currents (A, positive = discharge), shape (n_steps,).
    c_n0_mol_m3, c_p0_mol_m3 : float
        Initial uniform electrode concentrations (mol/m3).
    temperature_k : float
        Cell temperature (K).
    sets : ParameterSets
        The cell's factors on the built one (one set).
    backend : str
        Engine backend (``"auto"``, ``"numba"``, ``"numpy"``).
    hysteresis : Hysteresis
        Half-width, rate and initial state.
    time_s : numpy.ndarray
        Report times (s from the start), increasing.

    Returns
    -------
    HysteresisRun
    """
    if model.thermal is not None:
        raise SimulationError("the engine's hysteresis runs on isothermal cells")
    m = float(hysteresis.half_width_v)
    if not m >= 0.0:
        raise SimulationError(f"hysteresis half-width must be >= 0 V, got {m}")
    duration_s = np.asarray(duration_s, dtype=float)
    current = np.asarray(current_a, dtype=float)
    relax = float(hysteresis.relax_per_s)
    if not relax >= 0.0:
        raise SimulationError(f"hysteresis relaxation rate must be >= 0 1/s, got {relax}")
    h = hysteresis_states(hysteresis.initial_state, duration_s, current, hysteresis.rate_per_c, relax)
    shifted = _shifted(model, m)
    runs = run_cells(shifted, modal, duration_s, current, c_n0_mol_m3=c_n0_mol_m3, c_p0_mol_m3=c_p0_mol_m3,
                     temperature_k=temperature_k, sets=sets, backend=backend, keep_states=True)
    edges = np.concatenate([[0.0], np.cumsum(duration_s)])
    cut = model.lower_cutoff_v
    start_total = runs.start_voltage_v[0] + m * h[:-1]
    end_total = runs.end_voltage_v[0] + m * h[1:]
    with np.errstate(invalid="ignore"):
        below = (start_total < cut) | (end_total < cut)
    n_steps = duration_s.size
    kernel_step = int(runs.cutoff_step[0])
    end_time = float(edges[-1])
    reached = False
    if below.any() or runs.reached_cutoff[0]:
        reached = True
        k = int(np.argmax(below)) if below.any() else kernel_step
        k = min(k, kernel_step)
        if np.isnan(start_total[k]) or start_total[k] < cut:
            end_time = float(edges[k])
        else:
            upper = duration_s[k] if k < kernel_step else float(runs.end_time_s[0]) - edges[k]
            end_time = float(edges[k]) + _root_in_step(model, modal, runs, duration_s, current, k, upper,
                                                        m, float(h[k]), hysteresis.rate_per_c, relax)
    time_s = np.asarray(time_s, dtype=float)
    keep = time_s < end_time if reached else time_s <= end_time
    t_out = time_s[keep]
    h_out = states_at_times(edges[:-1], h, duration_s, current, hysteresis.rate_per_c, t_out, relax)
    v_cell = voltages_at_times(shifted, runs, modal, duration_s, current, t_out)[0] + m * h_out
    h_end = float(states_at_times(edges[:-1], h, duration_s, current, hysteresis.rate_per_c,
                                  np.array([end_time]), relax)[0]) if n_steps else float(hysteresis.initial_state)
    return HysteresisRun(time_s=t_out, cell_voltage_v=v_cell, hysteresis_state=h_out, end_time_s=end_time,
                         reached_cutoff=reached, final_state=h_end, backend=f"{runs.extra['backend']}+hysteresis")


def _root_in_step(model: LinearSpm, modal: ModalSystem, runs: CellRuns, duration_s: np.ndarray, current: np.ndarray,
                  k: int,
                  upper_s: float, m: float, h_k: float, rate_per_c: float, relax_per_s: float = 0.0) -> float:
    """Time into step ``k`` (s) at which the total voltage meets the cut-off (Illinois regula falsi on ``[0, upper_s]``)."""
    batch = runs.extra["batch"]
    z_k = states_at(batch.lam, batch.drive, runs.extra["checkpoints"], duration_s, current, np.array([k]),
                    runs.extra["stride"])
    i_k = float(current[k])
    cut = model.lower_cutoff_v

    def f(tau: float) -> float:
        decay, phi = step_coefficients(batch.lam, np.array([[tau]]))
        s = (decay * z_k + phi * batch.drive * i_k) @ modal.surface_weights.T
        v = model.cell_voltage_v(s[:, 0], s[:, 1], i_k, batch.temperature_k, batch.eps_n, batch.eps_p,
                                 batch.height_m)
        return float(v[0]) + m * float(hysteresis_step(h_k, i_k, tau, rate_per_c, relax_per_s)) - cut

    lo, hi = 0.0, float(upper_s)
    f_lo, f_hi = f(lo), f(hi)
    if f_hi >= 0.0:
        return hi
    side = 0
    for _ in range(_MAX_ROOT_ITERATIONS):
        if hi - lo <= CUTOFF_TIME_TOL_S:
            break
        mid = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not (np.isfinite(mid) and lo < mid < hi):
            mid = 0.5 * (lo + hi)
        f_mid = f(mid)
        if abs(f_mid) < 1e-13:
            return mid
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
