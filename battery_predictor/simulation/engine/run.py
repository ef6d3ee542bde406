"""Cell runs on piecewise-constant currents: voltage at every step and the exact cut-off time.

The particle states at every step boundary come from the exact modal recurrence
(:mod:`battery_predictor.simulation.engine.modal`); the cell voltage is PyBaMM's voltage
expression, just after each step start (under the step's current, right-continuous) and at each
step end (under the same current). The fused kernel (:mod:`~battery_predictor.simulation.engine.kernel`)
does both in one compiled loop per set; the two-pass path (NumPy, or when the states are kept for
reports inside steps) evaluates the voltage on all boundaries at once afterwards. The run ends at the
first step whose start or end voltage is below the lower cut-off: at the step start when the
start voltage is, else at the root of the voltage inside the step (regula falsi on the exact
within-step solution), which is where PyBaMM's ``Minimum voltage`` event stops its solver. A
voltage that dips below the cut-off and recovers within one constant-current step is not seen.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.engine.kernel import (
    PARALLEL_MIN_SETS,
    Kernel,
    VoltageKernels,
    forget_kernel,
    fused_kernel,
    voltage_kernels,
)
from battery_predictor.simulation.engine.modal import (
    ModalSystem,
    boundary_surfaces,
    numba_available,
    states_at,
    step_coefficients,
)
from battery_predictor.simulation.engine.model import (
    EPS_N,
    EPS_P,
    HEIGHT,
    LinearSpm,
)
from battery_predictor.simulation.engine.thermal import (
    TABLE_RANGE_K,
    DiffusivityTemperature,
    ThermalTrace,
    split_steps,
    thermal_recurrence,
)

LOG = logging.getLogger(__name__)
#: Cut-off times are located to this accuracy (s).
CUTOFF_TIME_TOL_S = 1e-7
#: A cell voltage above this (V) means the model left its range (a particle filled past its maximum
#: concentration, e.g. a charge pulse on a full cell); no lithium-ion chemistry gets there.
MAX_CELL_VOLTAGE_V = 6.0
_MAX_ROOT_ITERATIONS = 100


@dataclass(frozen=True)
class ParameterSets:
    """Cells that differ from the built cell by factors on geometric and transport values.

    Every attribute is a factor (1 = the built value), a float or an array of shape (n_sets,);
    ``heat_rate`` (lumped thermal cells) is the factor on ``dT/dt``, the built cell's volume-averaged
    heat capacity over the set's (:class:`~battery_predictor.simulation.engine.thermal.HeatCapacity`).
    None of them needs a PyBaMM rebuild (see :mod:`battery_predictor.simulation.engine.model`); the
    maximum concentrations only where :func:`~battery_predictor.simulation.engine.model.c_max_scaling_holds`.
    """

    radius_n: object = 1.0
    radius_p: object = 1.0
    diffusivity_n: object = 1.0
    diffusivity_p: object = 1.0
    thickness_n: object = 1.0
    thickness_p: object = 1.0
    fraction_n: object = 1.0
    fraction_p: object = 1.0
    height: object = 1.0
    c_max_n: object = 1.0
    c_max_p: object = 1.0
    heat_rate: object = 1.0

    def size(self) -> int:
        """Number of sets (1 when every factor is a scalar)."""
        sizes = {np.size(v) for v in vars(self).values()} - {1}
        if len(sizes) > 1:
            raise SimulationError(f"parameter set factors have different lengths: {sorted(sizes)}")
        return sizes.pop() if sizes else 1

    def arrays(self, n_sets: int) -> dict[str, np.ndarray]:
        """Every factor as an array of shape (n_sets,)."""
        out = {}
        for key, value in vars(self).items():
            arr = np.broadcast_to(np.asarray(value, dtype=float), (n_sets,))
            if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
                raise SimulationError(f"parameter set factor {key} must be finite and > 0")
            out[key] = arr
        return out


@dataclass
class CellRuns:
    """Runs of one or many cells on the same steps.

    Attributes
    ----------
    step_start_s : numpy.ndarray
        Step start times (s), shape (n_steps,).
    start_voltage_v : numpy.ndarray
        Cell voltage (V) just after each step start, shape (n_sets, n_steps); NaN from the
        step at whose start the run had ended.
    end_voltage_v : numpy.ndarray
        Cell voltage (V) at each step end under the step's current; NaN from the cut-off step on.
    end_time_s : numpy.ndarray
        When each run ended (s): at the cut-off, else at the end of the steps.
    reached_cutoff : numpy.ndarray
        True where the cell reached its lower cut-off.
    cutoff_step : numpy.ndarray
        Index of the step in which the run ended (n_steps when it did not).
    final_state : tuple of numpy.ndarray
        Negative and positive particle states at ``end_time_s`` (stoichiometry profiles,
        (n_sets, n) each), to continue from with ``run_cells(..., initial_state=...)``.
    """

    step_start_s: np.ndarray
    start_voltage_v: np.ndarray
    end_voltage_v: np.ndarray
    end_time_s: np.ndarray
    reached_cutoff: np.ndarray
    cutoff_step: np.ndarray
    final_state: tuple[np.ndarray, np.ndarray]
    extra: dict = field(default_factory=dict)


@dataclass(frozen=True)
class _Batch:
    """Per-set arrays of one run: modal eigenvalues, inputs, voltage inputs, temperature."""

    lam: np.ndarray
    drive: np.ndarray
    eps_n: np.ndarray
    eps_p: np.ndarray
    height_m: np.ndarray
    temperature_k: np.ndarray
    heat_rate: np.ndarray | None = None


def batch_arrays(model: LinearSpm, modal: ModalSystem, sets: ParameterSets, n_sets: int,
                 temperature_k: npt.ArrayLike) -> _Batch:
    """The per-set arrays :func:`run_cells` computes from ``sets`` and ``temperature_k`` for ``n_sets`` sets.

    A caller that runs the same sets at the same temperature many times (``EnginePack``: every route
    answer) computes them once and passes them as ``run_cells(..., batch=...)``.
    """
    return _batch(model, modal, sets, n_sets, temperature_k)


def _batch(model: LinearSpm, modal: ModalSystem, sets: ParameterSets, n_sets: int,
           temperature_k: npt.ArrayLike) -> _Batch:
    f = sets.arrays(n_sets)
    a_n = f["diffusivity_n"] / f["radius_n"] ** 2
    a_p = f["diffusivity_p"] / f["radius_p"] ** 2
    b_n = 1.0 / (f["fraction_n"] * f["thickness_n"] * f["height"] * f["c_max_n"])
    b_p = 1.0 / (f["fraction_p"] * f["thickness_p"] * f["height"] * f["c_max_p"])
    built = model.built_values
    return _Batch(
        lam=modal.eigenvalues_per_s[None, :] * modal.electrode_factors(a_n, a_p),
        drive=modal.input_per_a_s[None, :] * modal.electrode_factors(b_n, b_p),
        eps_n=built[EPS_N] * f["fraction_n"] * f["thickness_n"] * f["c_max_n"] / f["radius_n"],
        eps_p=built[EPS_P] * f["fraction_p"] * f["thickness_p"] * f["c_max_p"] / f["radius_p"],
        height_m=built[HEIGHT] * f["height"],
        temperature_k=np.broadcast_to(np.asarray(temperature_k, dtype=float), (n_sets,)),
        heat_rate=f["heat_rate"],
    )


def _voltage(model: LinearSpm, batch: _Batch, surfaces: np.ndarray, current_a: np.ndarray,
             temperature_k: np.ndarray | None = None, kernels: VoltageKernels | None = None) -> np.ndarray:
    """Cell voltage (V) for surfaces (n_sets, n, 2), currents broadcast to (n_sets, n) and cell temperatures
    (K, (n_sets, n); the batch's isothermal temperature when None).

    With ``kernels`` (isothermal only) the compiled printed voltage evaluates it, without the GIL.
    """
    if kernels is not None and temperature_k is None:
        return compiled_voltage(kernels, batch, surfaces, current_a)
    col = (slice(None), None)
    temperature_k = batch.temperature_k[col] if temperature_k is None else temperature_k
    return model.cell_voltage_v(surfaces[..., 0], surfaces[..., 1], current_a, temperature_k,
                                batch.eps_n[col], batch.eps_p[col], batch.height_m[col])


def compiled_voltage(kernels: VoltageKernels, batch: _Batch, surfaces: np.ndarray,
                     current_a: npt.ArrayLike) -> np.ndarray:
    """Cell voltage (V, (n_sets, n)) of an isothermal batch at surfaces (n_sets, n, 2) under cell currents
    (A) broadcast to (n_sets, n), by the compiled printed voltage (:class:`~.kernel.VoltageKernels`)."""
    shape = surfaces.shape[:2]
    current = np.asarray(current_a, dtype=float)
    if current.ndim != 2 or current.shape[0] not in (1, shape[0]):
        current = np.broadcast_to(current, shape)
    out = np.empty(shape)
    kernels.grid(np.ascontiguousarray(surfaces[..., 0]), np.ascontiguousarray(surfaces[..., 1]),
                 np.ascontiguousarray(np.broadcast_to(current, (current.shape[0], shape[1]))),
                 *(np.ascontiguousarray(np.broadcast_to(v, shape[:1]), dtype=float)
                   for v in (batch.temperature_k, batch.eps_n, batch.eps_p, batch.height_m)), out)
    return out


def run_cells(model: LinearSpm, modal: ModalSystem, duration_s: npt.ArrayLike, cell_current_a: npt.ArrayLike, *,
              c_n0_mol_m3: npt.ArrayLike | None = None,
              c_p0_mol_m3: npt.ArrayLike | None = None, temperature_k: npt.ArrayLike, sets: ParameterSets | None = None, backend: str = "auto",
              keep_states: bool = False, initial_state: tuple[np.ndarray, np.ndarray] | None = None,
              initial_temperature_k: npt.ArrayLike | None = None,
              diffusivity_temperature: DiffusivityTemperature | None = None,
              batch: _Batch | None = None) -> CellRuns:
    """Run cells from uniform particles through constant-current steps until the cut-off.

    Parameters
    ----------
    model, modal : LinearSpm, ModalSystem
        The extracted cell and its modal form.
    duration_s, cell_current_a : array_like
        Step lengths (s, > 0) and cell currents (A, positive = discharge), shape (n_steps,).
    c_n0_mol_m3, c_p0_mol_m3 : float or array_like
        Initial (uniform) electrode concentrations in mol/m3, scalar or (n_sets,).
    initial_state : tuple of numpy.ndarray, optional
        Instead of the concentrations: particle states (stoichiometry profiles, (n,) or
        (n_sets, n) each), e.g. a previous run's :attr:`CellRuns.final_state`.
    temperature_k : float or array_like
        Cell temperature in K (isothermal), scalar or (n_sets,); the ambient temperature of a lumped
        thermal cell (``model.thermal``, see :mod:`~battery_predictor.simulation.engine.thermal`).
    initial_temperature_k : float or array_like, optional
        Thermal cells: the cell temperature at the start (K); None starts at ``temperature_k``.
    diffusivity_temperature : DiffusivityTemperature, optional
        Thermal cells: the diffusivities' temperature dependence relative to ``temperature_k``
        (:func:`~battery_predictor.simulation.engine.thermal.diffusivity_temperature`); required
        for a thermal model.
    sets : ParameterSets, optional
        Cells that differ from the built one; None runs the built cell.
    backend : str
        ``"auto"`` (the fused Numba kernel when available), ``"numba"`` or ``"numpy"``.
    keep_states : bool
        Keep the modal state at every step boundary (for :func:`voltages_at_times`); this runs the
        recurrence and the voltage in two passes.
    batch : optional
        ``batch_arrays(model, modal, sets, n_sets, temperature_k)`` of exactly these ``sets`` and
        ``temperature_k``, computed once by a caller that repeats them (recomputed when its number of
        sets does not match).

    Returns
    -------
    CellRuns
        ``extra["backend"]`` names the path that ran: ``"numba-fused"``, ``"numba"`` or ``"numpy"``
        (``"numba-thermal"`` / ``"numpy-thermal"`` for a thermal cell, whose ``extra["temperature_k"]``
        holds the cell temperature at every step boundary, (n_sets, n_steps + 1), and
        ``extra["final_temperature_k"]`` the one at ``end_time_s``).
    """
    duration_s = np.asarray(duration_s, dtype=float)
    current = np.asarray(cell_current_a, dtype=float)
    if duration_s.ndim != 1 or duration_s.shape != current.shape or duration_s.size == 0:
        raise SimulationError("steps: durations and currents must be 1-D of equal non-zero length")
    if not (np.isfinite(duration_s).all() and (duration_s > 0).all() and np.isfinite(current).all()):
        raise SimulationError("steps: durations must be finite and > 0 s, currents finite")
    if backend not in ("auto", "numba", "numpy"):
        raise SimulationError(f"unknown engine backend '{backend}' (auto, numba or numpy)")
    sets = sets or ParameterSets()
    if (initial_state is None) == (c_n0_mol_m3 is None or c_p0_mol_m3 is None):
        raise SimulationError("give either both initial concentrations or an initial state")
    n_state_sets = 1 if initial_state is None else max(np.atleast_2d(y).shape[0] for y in initial_state)
    n_sets = max(batch.lam.shape[0] if batch is not None else sets.size(),  # a given batch was made of these sets
                 np.size(c_n0_mol_m3 if c_n0_mol_m3 is not None else 0.0),
                 np.size(c_p0_mol_m3 if c_p0_mol_m3 is not None else 0.0), np.size(temperature_k), n_state_sets)
    if batch is None or batch.lam.shape[0] != n_sets:
        batch = _batch(model, modal, sets, n_sets, temperature_k)
    if initial_state is None:
        c_max_n = model.blocks[0].scale_mol_m3 * np.broadcast_to(np.asarray(sets.c_max_n, dtype=float), (n_sets,))
        c_max_p = model.blocks[1].scale_mol_m3 * np.broadcast_to(np.asarray(sets.c_max_p, dtype=float), (n_sets,))
        c_n0 = np.broadcast_to(np.asarray(c_n0_mol_m3, dtype=float), (n_sets,))
        c_p0 = np.broadcast_to(np.asarray(c_p0_mol_m3, dtype=float), (n_sets,))
        y_n = np.outer(c_n0 / c_max_n, np.ones(model.blocks[0].b_vector_per_a_s.size))
        y_p = np.outer(c_p0 / c_max_p, np.ones(model.blocks[1].b_vector_per_a_s.size))
    else:
        y_n, y_p = (np.broadcast_to(np.atleast_2d(np.asarray(y, dtype=float)), (n_sets, blk.b_vector_per_a_s.size))
                    for y, blk in zip(initial_state, model.blocks))
    z0 = np.ascontiguousarray(np.broadcast_to(modal.modal_state(y_n, y_p), (n_sets, modal.n_modes)))
    edges = np.concatenate([[0.0], np.cumsum(duration_s)])
    if model.thermal is not None:
        if diffusivity_temperature is None:
            raise SimulationError("a lumped thermal cell needs its diffusivities' temperature dependence "
                                  "(diffusivity_temperature)")
        t0 = temperature_k if initial_temperature_k is None else initial_temperature_k
        t0 = np.broadcast_to(np.asarray(t0, dtype=float), (n_sets,))
        return _run_thermal(model, modal, batch, z0, t0, duration_s, current, edges, backend, diffusivity_temperature,
                            stride=1 if keep_states else (8 if n_sets <= 16 else 64))
    kernel = None if keep_states or backend == "numpy" else fused_kernel(model, parallel=n_sets >= PARALLEL_MIN_SETS)
    if kernel is not None:
        from numba.core.errors import NumbaError

        try:
            return _run_fused(kernel, model, modal, batch, z0, duration_s, current, edges)
        except NumbaError as exc:  # the printed voltage did not compile: the NumPy voltage is the same expression
            LOG.warning("engine: the fused kernel does not compile for this model (%s); using the two-pass path",
                        str(exc).splitlines()[0])
            forget_kernel(model)
    return _run_two_pass(model, modal, batch, z0, duration_s, current, edges, backend,
                         stride=1 if keep_states else 64)


def _run_fused(kernel: Kernel, model: LinearSpm, modal: ModalSystem, batch: _Batch, z0: np.ndarray, duration_s: np.ndarray,
               current: np.ndarray, edges: np.ndarray) -> CellRuns:
    n_sets, n_steps = z0.shape[0], duration_s.size
    start_v = np.full((n_sets, n_steps), np.nan)
    end_v = np.full((n_sets, n_steps), np.nan)
    end_time = np.empty(n_sets)
    cutoff_step = np.empty(n_sets, dtype=np.int64)
    at_start = np.empty(n_sets, dtype=np.bool_)
    z_end = np.empty((n_sets, modal.n_modes))
    kernel(np.ascontiguousarray(batch.lam), np.ascontiguousarray(batch.drive), np.ascontiguousarray(z0), duration_s,
           current, np.ascontiguousarray(modal.surface_weights), np.ascontiguousarray(batch.temperature_k),
           np.ascontiguousarray(batch.eps_n), np.ascontiguousarray(batch.eps_p), np.ascontiguousarray(batch.height_m),
           float(model.lower_cutoff_v), CUTOFF_TIME_TOL_S, start_v, end_v, end_time, cutoff_step, at_start, z_end)
    if not np.all(np.isfinite(end_time)):
        raise SimulationError("the engine produced non-finite voltages (a particle emptied or filled?)")
    _check_range(start_v, end_v, edges)
    ended_at_start = np.nonzero(at_start)[0]
    start_v[ended_at_start, cutoff_step[ended_at_start]] = np.nan
    return CellRuns(step_start_s=edges[:-1], start_voltage_v=start_v, end_voltage_v=end_v, end_time_s=end_time,
                    reached_cutoff=cutoff_step < n_steps, cutoff_step=cutoff_step,
                    final_state=modal.block_states(z_end), extra={"backend": "numba-fused", "batch": batch})


def _check_range(start_v: np.ndarray, end_v: np.ndarray, edges: np.ndarray) -> None:
    """Raise when a cell voltage left the physical range (see :data:`MAX_CELL_VOLTAGE_V`)."""
    if not ((start_v > MAX_CELL_VOLTAGE_V).any() or (end_v > MAX_CELL_VOLTAGE_V).any()):
        return  # the common case, in two comparisons (NaN compares False, as NaN -> 0 did below)
    high = (np.nan_to_num(start_v, nan=0.0) > MAX_CELL_VOLTAGE_V) | (np.nan_to_num(end_v, nan=0.0) > MAX_CELL_VOLTAGE_V)
    if high.any():
        step = int(np.argmax(high.any(axis=0)))
        raise SimulationError(f"the cell was charged past full at {edges[step]:.0f} s (the model's voltage left "
                              f"its range, above {MAX_CELL_VOLTAGE_V:.0f} V): the initial state is too high for "
                              "the charge that follows")


def _run_two_pass(model: LinearSpm, modal: ModalSystem, batch: _Batch, z0: np.ndarray, duration_s: np.ndarray,
                  current: np.ndarray, edges: np.ndarray, backend: str, stride: int) -> CellRuns:
    """States at every boundary (Numba or NumPy recurrence), then the voltage on all of them and the cut-off root.

    With Numba the voltage and the root are the compiled printed voltage's (the fused kernel's root, without
    the GIL); otherwise, or when it does not compile, PyBaMM's NumPy voltage and :func:`_cutoff_in_step`.
    """
    kernels = None if backend == "numpy" else voltage_kernels(model)
    if kernels is not None:
        from numba.core.errors import NumbaError

        try:
            return _two_pass(model, modal, batch, z0, duration_s, current, edges, backend, stride, kernels)
        except NumbaError as exc:  # the printed voltage did not compile: the NumPy voltage is the same expression
            LOG.warning("engine: the compiled voltage does not compile for this model (%s); using NumPy's",
                        str(exc).splitlines()[0])
            forget_kernel(model)
    return _two_pass(model, modal, batch, z0, duration_s, current, edges, backend, stride, None)


def _two_pass(model: LinearSpm, modal: ModalSystem, batch: _Batch, z0: np.ndarray, duration_s: np.ndarray,
              current: np.ndarray, edges: np.ndarray, backend: str, stride: int,
              kernels: VoltageKernels | None) -> CellRuns:
    n_sets = z0.shape[0]
    surfaces, checkpoints, z_end = boundary_surfaces(batch.lam, batch.drive, z0, duration_s, current,
                                                     modal.surface_weights, stride=stride, backend=backend)
    start_v = _voltage(model, batch, surfaces[:, :-1], current[None, :], kernels=kernels)
    end_v = _voltage(model, batch, surfaces[:, 1:], current[None, :], kernels=kernels)
    if not (np.all(np.isfinite(start_v)) and np.all(np.isfinite(end_v))):
        raise SimulationError("the engine produced non-finite voltages (a particle emptied or filled?)")
    _check_range(start_v, end_v, edges)
    cut = model.lower_cutoff_v
    below = (start_v < cut) | (end_v < cut)
    any_below = below.any(axis=1)
    cutoff_step = np.where(any_below, below.argmax(axis=1), duration_s.size)
    end_time = np.full(n_sets, edges[-1])
    at_start = any_below & (start_v[np.arange(n_sets), np.minimum(cutoff_step, duration_s.size - 1)] < cut)
    end_time[at_start] = edges[cutoff_step[at_start]]
    inside = np.nonzero(any_below & ~at_start)[0]
    z_final = z_end.copy()
    if inside.size:
        z_k = states_at(batch.lam[inside], batch.drive[inside], checkpoints[inside], duration_s, current,
                        cutoff_step[inside], stride)
        k = cutoff_step[inside]
        if kernels is None:
            tau = _cutoff_in_step(model, modal, _take(batch, inside), z_k, duration_s[k], current[k])
        else:
            tau = _compiled_cutoff(kernels, model, modal, _take(batch, inside), z_k, duration_s[k], current[k],
                                   start_v[inside, k], end_v[inside, k])
        end_time[inside] = edges[cutoff_step[inside]] + tau
        decay, phi = step_coefficients(batch.lam[inside], tau[:, None])
        z_final[inside] = decay * z_k + phi * batch.drive[inside] * current[cutoff_step[inside]][:, None]
    starts = np.nonzero(at_start)[0]
    if starts.size:
        z_final[starts] = states_at(batch.lam[starts], batch.drive[starts], checkpoints[starts], duration_s, current,
                                    cutoff_step[starts], stride)
    cols = np.arange(duration_s.size)[None, :]
    first_gone = cutoff_step + np.where(at_start, 0, 1)  # the cut-off step's start is kept when above the cut-off
    start_v = np.where(cols >= first_gone[:, None], np.nan, start_v)
    end_v = np.where(cols >= cutoff_step[:, None], np.nan, end_v)
    used = "numpy" if backend == "numpy" or not numba_available() else "numba"
    extra = {"checkpoints": checkpoints, "stride": stride, "z_end": z_end, "lam": batch.lam, "drive": batch.drive,
             "batch": batch, "backend": used, "surfaces": surfaces, "kernels": kernels}
    return CellRuns(step_start_s=edges[:-1], start_voltage_v=start_v, end_voltage_v=end_v, end_time_s=end_time,
                    reached_cutoff=any_below, cutoff_step=cutoff_step, final_state=modal.block_states(z_final),
                    extra=extra)


@dataclass(frozen=True)
class _ThermalSteps:
    """A thermal run's sub-steps (steps longer than the thermal step split) and their trace."""

    start_s: np.ndarray
    duration_s: np.ndarray
    current_a: np.ndarray
    owner: np.ndarray
    first: np.ndarray
    trace: ThermalTrace


def _run_thermal(model: LinearSpm, modal: ModalSystem, batch: _Batch, z0: np.ndarray, t0: np.ndarray,
                 duration_s: np.ndarray, current: np.ndarray, edges: np.ndarray, backend: str,
                 table: DiffusivityTemperature, stride: int) -> CellRuns:
    """Thermal cells: particle and temperature recurrence on sub-steps, then the voltage on every boundary."""
    n_sets = z0.shape[0]
    n_sub, owner, first, sub_h, sub_i, sub_start = _thermal_sub_steps(duration_s, current, edges)
    trace = thermal_recurrence(model, modal, batch.lam, batch.drive, z0, t0, batch.temperature_k, batch.eps_n,
                               batch.eps_p, batch.height_m, sub_h, sub_i, table, heat_rate=batch.heat_rate,
                               stride=stride, backend=backend)
    steps = _ThermalSteps(start_s=sub_start, duration_s=sub_h, current_a=sub_i, owner=owner, first=first, trace=trace)
    temps = trace.temperature_k
    start_v, end_v = _thermal_voltages(model, batch, trace, sub_i)
    sub_edges = np.append(sub_start, edges[-1])
    cut = model.lower_cutoff_v
    below = (start_v < cut) | (end_v < cut)
    any_below = below.any(axis=1)
    sub_cut = np.where(any_below, below.argmax(axis=1), owner.size)
    at_start = any_below & (start_v[np.arange(n_sets), np.minimum(sub_cut, owner.size - 1)] < cut)
    _check_thermal_run(start_v, end_v, temps, sub_cut, at_start, sub_edges)
    end_time = np.full(n_sets, edges[-1])
    end_time[at_start] = sub_edges[sub_cut[at_start]]
    final_t = temps[:, -1].copy()
    final_t[at_start] = temps[at_start, sub_cut[at_start]]
    z_final = trace.z_end.copy()
    ended = np.nonzero(any_below)[0]
    if ended.size:
        z_k = _trace_take(trace, ended).states_at(batch.lam[ended], batch.drive[ended], sub_h, sub_i,
                                                  modal.electrode_factors, sub_cut[ended])
        z_final[ended] = z_k
        inside = np.nonzero(any_below & ~at_start)[0]
        if inside.size:
            _thermal_cutoff_inside(model, modal, batch, steps, inside, z_k[np.searchsorted(ended, inside)],
                                   sub_cut[inside], end_time, z_final, final_t)
    cutoff_step, step_start_v, step_end_v = _thermal_step_view(steps, n_sub, start_v, end_v, any_below, at_start,
                                                               sub_cut)
    boundary = np.append(first, owner.size)
    extra = {"backend": f"{trace.backend}-thermal", "batch": batch, "thermal_steps": steps, "model": model,
             "lam": batch.lam, "drive": batch.drive, "stride": stride,
             "surfaces": trace.surfaces[:, boundary], "temperature_k": temps[:, boundary],
             "final_temperature_k": final_t}
    return CellRuns(step_start_s=edges[:-1], start_voltage_v=step_start_v, end_voltage_v=step_end_v,
                    end_time_s=end_time, reached_cutoff=any_below, cutoff_step=cutoff_step,
                    final_state=modal.block_states(z_final), extra=extra)


def _thermal_sub_steps(duration_s: np.ndarray, current: np.ndarray,
                       edges: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Steps longer than the thermal step split: (sub-steps per step, owning step, first sub-step of each step,
    sub-step durations, currents and start times)."""
    n_sub = split_steps(duration_s)
    owner = np.repeat(np.arange(duration_s.size), n_sub)
    first = np.concatenate([[0], np.cumsum(n_sub)[:-1]])
    sub_h = np.repeat(duration_s / n_sub, n_sub)
    sub_i = current[owner]
    sub_start = edges[owner] + (np.arange(owner.size) - first[owner]) * sub_h
    return n_sub, owner, first, sub_h, sub_i, sub_start


def _thermal_voltages(model: LinearSpm, batch: _Batch, trace: ThermalTrace,
                      sub_i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Voltages at each sub-step's start and end: the compiled kernel's (PyBaMM's printed voltage expression,
    NaN after each set's end, where the kernel stops) or NumPy's on the trace."""
    if trace.voltages_v is not None:
        start_v, end_v = trace.voltages_v
        return start_v, end_v
    temps = trace.temperature_k
    return (_voltage(model, batch, trace.surfaces[:, :-1], sub_i[None, :], temps[:, :-1]),
            _voltage(model, batch, trace.surfaces[:, 1:], sub_i[None, :], temps[:, 1:]))


def _check_thermal_run(start_v: np.ndarray, end_v: np.ndarray, temps: np.ndarray, sub_cut: np.ndarray,
                       at_start: np.ndarray, sub_edges: np.ndarray) -> None:
    """SimulationError unless voltages and temperatures are finite (and the temperature in the table's range)
    up to each set's end, and the voltages within range."""
    n_sub_steps = start_v.shape[1]
    cols = np.arange(n_sub_steps)[None, :]
    if not (np.all(np.isfinite(start_v[cols <= sub_cut[:, None]]))
            and np.all(np.isfinite(end_v[cols < (sub_cut + ~at_start)[:, None]]))):
        raise SimulationError("the engine produced non-finite voltages (a particle emptied or filled?)")
    lo, hi = TABLE_RANGE_K
    valid_t = temps[np.arange(n_sub_steps + 1)[None, :] <= (sub_cut + ~at_start)[:, None]]
    if not (np.all(np.isfinite(valid_t)) and np.all((valid_t > lo) & (valid_t < hi))):
        raise SimulationError(f"the lumped cell temperature left {lo:.0f}..{hi:.0f} K")
    _check_range(start_v, end_v, sub_edges)


def _thermal_cutoff_inside(model: LinearSpm, modal: ModalSystem, batch: _Batch, steps: _ThermalSteps,
                           inside: np.ndarray, z_k: np.ndarray, k: np.ndarray, end_time: np.ndarray,
                           z_final: np.ndarray, final_t: np.ndarray) -> None:
    """The sets ``inside`` meet the cut-off inside sub-step ``k`` (states ``z_k`` at its start): their end time,
    final states and temperatures, written into ``end_time``, ``z_final`` and ``final_t``."""
    trace, sub_h, sub_i = steps.trace, steps.duration_s, steps.current_a
    sub = _take(batch, inside)
    g = trace.diffusivity_factor[inside, k]
    lam = sub.lam * modal.electrode_factors(g[:, 0], g[:, 1])
    t_k = trace.temperature_k[inside, k]
    s_k = trace.surfaces[inside, k]
    assert model.thermal is not None  # a thermal run
    # the root is found with the temperature's Euler line inside the step (the voltage moves by
    # about a millivolt per kelvin; the step's temperature change is a few hundredths of one)
    r_k = sub.heat_rate * model.thermal.temperature_rate_k_s(s_k[:, 0], s_k[:, 1], sub_i[k], t_k,
                                                             sub.temperature_k, sub.eps_n, sub.eps_p,
                                                             sub.height_m)

    def euler_temperature(tau: np.ndarray, s_tau: np.ndarray, t_k: np.ndarray = t_k,
                          r_k: np.ndarray = r_k) -> np.ndarray:
        return t_k + tau * r_k

    tau = _cutoff_in_step(model, modal, _Batch(lam, sub.drive, sub.eps_n, sub.eps_p, sub.height_m, t_k),
                          z_k, sub_h[k], sub_i[k], temperature_at=euler_temperature)
    end_time[inside] = steps.start_s[k] + tau
    decay, phi = step_coefficients(lam, tau[:, None])
    z_final[inside] = decay * z_k + phi * sub.drive * sub_i[k][:, None]
    final_t[inside] = _temperature_within(model, sub, s_k, z_final[inside] @ modal.surface_weights.T,
                                          sub_i[k], t_k, tau)


def _thermal_step_view(steps: _ThermalSteps, n_sub: np.ndarray, start_v: np.ndarray, end_v: np.ndarray,
                       any_below: np.ndarray, at_start: np.ndarray,
                       sub_cut: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The step-level view: the cut-off step, start voltages at each step's first sub-step and end voltages at
    its last, NaN from the cut-off on."""
    owner, first = steps.owner, steps.first
    n_steps = first.size
    cutoff_step = np.where(any_below, owner[np.minimum(sub_cut, owner.size - 1)], n_steps)
    last = first + n_sub - 1
    step_start_v, step_end_v = start_v[:, first], end_v[:, last]
    step_at_start = at_start & (sub_cut == first[np.minimum(cutoff_step, n_steps - 1)])
    cols = np.arange(n_steps)[None, :]
    first_gone = cutoff_step + np.where(step_at_start, 0, 1)
    step_start_v = np.where(cols >= first_gone[:, None], np.nan, step_start_v)
    step_end_v = np.where(cols >= cutoff_step[:, None], np.nan, step_end_v)
    return cutoff_step, step_start_v, step_end_v


def _temperature_within(model: LinearSpm, batch: _Batch, s_k: np.ndarray, s_tau: np.ndarray, current_a: npt.ArrayLike,
                        t_k: np.ndarray, tau: npt.ArrayLike) -> np.ndarray:
    """Cell temperature (K) ``tau`` into a step: Heun's step of length ``tau`` from ``(s_k, t_k)`` (surfaces
    (..., 2) at the step start and at ``tau``), the recurrence's own rule, so that it needs nothing past ``tau``
    (the step's end may lie past a cut-off where the cell emptied)."""
    thermal = model.thermal
    assert thermal is not None  # a thermal run

    def rate(s: np.ndarray, t: np.ndarray) -> np.ndarray:
        return batch.heat_rate * thermal.temperature_rate_k_s(s[..., 0], s[..., 1], current_a, t,
                                                                    batch.temperature_k, batch.eps_n, batch.eps_p,
                                                                    batch.height_m)

    r0 = rate(s_k, t_k)
    tau = np.asarray(tau, dtype=float)
    return t_k + 0.5 * tau * (r0 + rate(s_tau, t_k + tau * r0))


def _trace_take(trace: ThermalTrace, idx: np.ndarray) -> ThermalTrace:
    return ThermalTrace(surfaces=trace.surfaces[idx], temperature_k=trace.temperature_k[idx],
                        diffusivity_factor=trace.diffusivity_factor[idx], states=trace.states[idx],
                        stride=trace.stride, z_end=trace.z_end[idx], backend=trace.backend)


def _take(batch: _Batch, idx: np.ndarray) -> _Batch:
    return _Batch(*(getattr(batch, name)[idx] for name in batch.__dataclass_fields__))


def _within_step(modal: ModalSystem, batch: _Batch, z_k: np.ndarray, tau_s: np.ndarray,
                 current_a: np.ndarray) -> np.ndarray:
    """Surface values (n, 2) at ``tau_s`` into the step from modal states ``z_k`` (n, n_modes)."""
    decay, phi = step_coefficients(batch.lam, tau_s[:, None])
    z = decay * z_k + phi * batch.drive * current_a[:, None]
    return z @ modal.surface_weights.T


def _compiled_cutoff(kernels: VoltageKernels, model: LinearSpm, modal: ModalSystem, batch: _Batch, z_k: np.ndarray,
                     h_s: np.ndarray, current_a: np.ndarray, v0: np.ndarray, v1: np.ndarray) -> np.ndarray:
    """:func:`_cutoff_in_step` (isothermal) by the fused kernel's compiled root: time into the step (s) at which
    the voltage, ``v0`` (V) at the step start and ``v1`` at its end, meets the cut-off."""
    def c(a: npt.ArrayLike) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=float)

    n = z_k.shape[0]
    per_set = (np.broadcast_to(v, (n,)) for v in (batch.temperature_k, batch.eps_n, batch.eps_p, batch.height_m))
    return kernels.cutoff_roots(c(z_k), c(batch.lam), c(batch.drive), c(modal.surface_weights), c(h_s), c(current_a),
                                c(v0), c(v1), *(c(v) for v in per_set), float(model.lower_cutoff_v),
                                CUTOFF_TIME_TOL_S)


def _cutoff_in_step(model: LinearSpm, modal: ModalSystem, batch: _Batch, z_k: np.ndarray, h_s: np.ndarray,
                    current_a: np.ndarray,
                    temperature_at: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """Time into the step (s) at which the voltage meets the cut-off (Illinois regula falsi, vectorised).

    With ``temperature_at(tau, surfaces)`` (thermal cells) the temperature inside the step is its value.
    """
    cut = model.lower_cutoff_v

    def f(tau: np.ndarray) -> np.ndarray:
        s = _within_step(modal, batch, z_k, tau, current_a)
        temperature_k = batch.temperature_k if temperature_at is None else temperature_at(tau, s)
        return model.cell_voltage_v(s[:, 0], s[:, 1], current_a, temperature_k, batch.eps_n, batch.eps_p,
                                    batch.height_m) - cut

    lo, hi = np.zeros_like(h_s), h_s.copy()
    f_lo, f_hi = f(lo), f(hi)
    side = np.zeros(h_s.size, dtype=int)
    for _ in range(_MAX_ROOT_ITERATIONS):
        if np.all(hi - lo <= CUTOFF_TIME_TOL_S):
            break
        mid = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        mid = np.where(np.isfinite(mid) & (mid > lo) & (mid < hi), mid, 0.5 * (lo + hi))
        f_mid = f(mid)
        upper = f_mid < 0.0  # the root lies below mid
        hi = np.where(upper, mid, hi)
        lo = np.where(upper, lo, mid)
        f_hi_new = np.where(upper, f_mid, np.where(side == -1, 0.5 * f_hi, f_hi))
        f_lo_new = np.where(upper, np.where(side == 1, 0.5 * f_lo, f_lo), f_mid)
        side = np.where(upper, 1, -1)
        f_hi, f_lo = f_hi_new, f_lo_new
        done = np.abs(f_mid) < 1e-13
        lo = np.where(done, mid, lo)
        hi = np.where(done, mid, hi)
    return 0.5 * (lo + hi)


def states_at_times(runs: CellRuns, modal: ModalSystem, duration_s: npt.ArrayLike, cell_current_a: npt.ArrayLike,
                    time_s: npt.ArrayLike) -> np.ndarray:
    """Surface values (n_sets, n_times, 2) at ``time_s`` (right-continuous), from a run that kept its states."""
    if runs.extra.get("stride") != 1:
        raise SimulationError("states at arbitrary times need a run that kept every state (keep_states=True)")
    if "thermal_steps" in runs.extra:
        return _thermal_at_times(runs, modal, time_s)[0]
    duration_s = np.asarray(duration_s, dtype=float)
    current = np.asarray(cell_current_a, dtype=float)
    time_s = np.asarray(time_s, dtype=float)
    step = np.clip(np.searchsorted(runs.step_start_s, time_s, side="right") - 1, 0, duration_s.size - 1)
    tau = time_s - runs.step_start_s[step]
    out = runs.extra["surfaces"][:, step].copy()
    inside = np.nonzero(tau > 0.0)[0]
    if inside.size:
        z_start = runs.extra["checkpoints"][:, step[inside]]  # (n_sets, n_inside, n_modes)
        decay, phi = step_coefficients(runs.extra["lam"][:, None, :], tau[inside][None, :, None])
        z = decay * z_start + phi * runs.extra["drive"][:, None, :] * current[step[inside]][None, :, None]
        out[:, inside] = z @ modal.surface_weights.T
    return out


def set_surfaces_at_times(runs: CellRuns, modal: ModalSystem, duration_s: npt.ArrayLike, cell_current_a: npt.ArrayLike,
                          time_s: npt.ArrayLike, set_index: int) -> np.ndarray:
    """Surface values (n_times, 2) of one set at ``time_s`` (:func:`states_at_times`; compiled when the run was)."""
    kernels: VoltageKernels | None = runs.extra.get("kernels")
    if kernels is None or runs.extra.get("stride") != 1:
        return states_at_times(runs, modal, duration_s, cell_current_a, time_s)[set_index]
    current = np.ascontiguousarray(cell_current_a, dtype=float)
    time_s = np.asarray(time_s, dtype=float)
    step = np.clip(np.searchsorted(runs.step_start_s, time_s, side="right") - 1, 0, current.size - 1)
    tau = np.ascontiguousarray(time_s - runs.step_start_s[step])
    out = np.empty((time_s.size, 2))
    kernels.surfaces_within(runs.extra["checkpoints"][set_index], np.ascontiguousarray(runs.extra["lam"][set_index]),
                            np.ascontiguousarray(runs.extra["drive"][set_index]), modal.surface_weights, step, tau,
                            np.ascontiguousarray(current[step]), out)
    return out


def set_voltage_v(model: LinearSpm, runs: CellRuns, set_index: int, surfaces: np.ndarray, current_a: np.ndarray,
                  temperature_k: npt.ArrayLike) -> np.ndarray:
    """Cell voltage (V, (n,)) of one set of ``runs`` at surfaces (n, 2), cell currents (A, (n,)) and cell temperatures
    (K); by the compiled printed voltage when the run was isothermal and compiled."""
    batch = runs.extra["batch"]
    kernels: VoltageKernels | None = runs.extra.get("kernels")
    if kernels is not None and model.thermal is None:
        return compiled_voltage(kernels, _take(batch, np.array([set_index])), surfaces[None], current_a[None])[0]
    return model.cell_voltage_v(surfaces[:, 0], surfaces[:, 1], current_a, temperature_k, batch.eps_n[set_index],
                                batch.eps_p[set_index], batch.height_m[set_index])


def voltages_at_times(model: LinearSpm, runs: CellRuns, modal: ModalSystem, duration_s: npt.ArrayLike,
                      cell_current_a: npt.ArrayLike, time_s: npt.ArrayLike) -> np.ndarray:
    """Cell voltage (V, n_sets x n_times) at ``time_s`` under the current in force there (right-continuous).

    Times on a step start reuse the run's start voltages; the others are stepped into their step.
    """
    time_s = np.asarray(time_s, dtype=float)
    current = np.asarray(cell_current_a, dtype=float)
    step = np.clip(np.searchsorted(runs.step_start_s, time_s, side="right") - 1, 0, np.size(duration_s) - 1)
    if "thermal_steps" in runs.extra:
        surfaces, temperature_k = _thermal_at_times(runs, modal, time_s)
        return _voltage(model, runs.extra["batch"], surfaces, current[step][None, :], temperature_k)
    on_start = time_s == runs.step_start_s[step]
    out = runs.start_voltage_v[:, step].copy()
    inside = np.nonzero(~on_start | np.isnan(out).any(axis=0))[0]
    if inside.size:
        surfaces = states_at_times(runs, modal, duration_s, current, time_s[inside])
        out[:, inside] = _voltage(model, runs.extra["batch"], surfaces, current[step[inside]][None, :])
    return out


def _thermal_at_times(runs: CellRuns, modal: ModalSystem, time_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Surface values (n_sets, n_times, 2) and cell temperatures (K, (n_sets, n_times)) of a thermal run that
    kept every state, at ``time_s`` (right-continuous; the temperature linear inside each sub-step)."""
    steps: _ThermalSteps = runs.extra["thermal_steps"]
    trace = steps.trace
    if trace.stride != 1:
        raise SimulationError("states at arbitrary times need a run that kept every state (keep_states=True)")
    time_s = np.asarray(time_s, dtype=float)
    k = np.clip(np.searchsorted(steps.start_s, time_s, side="right") - 1, 0, steps.start_s.size - 1)
    tau = np.minimum(time_s - steps.start_s[k], steps.duration_s[k])
    g = trace.diffusivity_factor[:, k]  # (n_sets, n_times, 2)
    negative = np.arange(modal.n_modes) < modal.n_negative
    per_mode = np.where(negative[None, None, :], g[..., :1], g[..., 1:])
    decay, phi = step_coefficients(runs.extra["lam"][:, None, :] * per_mode, tau[None, :, None])
    z = decay * trace.states[:, k] + phi * runs.extra["drive"][:, None, :] * steps.current_a[k][None, :, None]
    surfaces = z @ modal.surface_weights.T
    batch = runs.extra["batch"]
    col = (slice(None), None)
    per_set = _Batch(lam=np.asarray(batch.lam)[col], drive=np.asarray(batch.drive)[col],
                     eps_n=np.asarray(batch.eps_n)[col], eps_p=np.asarray(batch.eps_p)[col],
                     height_m=np.asarray(batch.height_m)[col], temperature_k=np.asarray(batch.temperature_k)[col],
                     heat_rate=None if batch.heat_rate is None else np.asarray(batch.heat_rate)[col])
    temperature_k = _temperature_within(model_of(runs), per_set, trace.surfaces[:, k], surfaces,
                                        steps.current_a[k][None, :], trace.temperature_k[:, k], tau[None, :])
    return surfaces, temperature_k


def temperatures_at_times(runs: CellRuns, modal: ModalSystem, time_s: npt.ArrayLike) -> np.ndarray:
    """Cell temperature (K, (n_sets, n_times)) at ``time_s``: the lumped temperature of a thermal run that kept
    every state, else the run's isothermal temperature."""
    time_s = np.asarray(time_s, dtype=float)
    if "thermal_steps" in runs.extra:
        return _thermal_at_times(runs, modal, time_s)[1]
    return np.repeat(runs.extra["batch"].temperature_k[:, None], time_s.size, axis=1)


def thermal_state_at(runs: CellRuns, modal: ModalSystem, set_index: int, time_s: float) -> tuple[np.ndarray, float]:
    """Modal state (1, n_modes) and cell temperature (K) of one set of a thermal run that kept every state."""
    steps: _ThermalSteps = runs.extra["thermal_steps"]
    trace = steps.trace
    k = int(np.clip(np.searchsorted(steps.start_s, time_s, side="right") - 1, 0, steps.start_s.size - 1))
    tau = min(float(time_s) - float(steps.start_s[k]), float(steps.duration_s[k]))
    g = trace.diffusivity_factor[set_index, k]
    lam = runs.extra["lam"][set_index] * modal.electrode_factors(g[0], g[1])[0]
    decay, phi = step_coefficients(lam, tau)
    z = decay * trace.states[set_index, k] + phi * runs.extra["drive"][set_index] * steps.current_a[k]
    batch = _take(runs.extra["batch"], np.array([set_index]))
    s_tau = z[None, :] @ modal.surface_weights.T
    temperature_k = _temperature_within(model_of(runs), batch, trace.surfaces[set_index, k][None, :], s_tau,
                                        steps.current_a[k], trace.temperature_k[set_index, k:k + 1], tau)
    return z[None, :], float(temperature_k[0])


def model_of(runs: CellRuns) -> LinearSpm:
    """The extracted cell a run was made with."""
    return runs.extra["model"]
