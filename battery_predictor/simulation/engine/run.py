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
from dataclasses import dataclass, field

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.engine.kernel import PARALLEL_MIN_SETS, forget_kernel, fused_kernel
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

    Every attribute is a factor (1 = the built value), a float or an array of shape (n_sets,).
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


def _batch(model: LinearSpm, modal: ModalSystem, sets: ParameterSets, n_sets: int, temperature_k) -> _Batch:
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
    )


def _voltage(model: LinearSpm, batch: _Batch, surfaces: np.ndarray, current_a: np.ndarray) -> np.ndarray:
    """Cell voltage (V) for surfaces (n_sets, n, 2) and currents broadcast to (n_sets, n)."""
    col = (slice(None), None)
    return model.cell_voltage_v(surfaces[..., 0], surfaces[..., 1], current_a, batch.temperature_k[col],
                                batch.eps_n[col], batch.eps_p[col], batch.height_m[col])


def run_cells(model: LinearSpm, modal: ModalSystem, duration_s, cell_current_a, *, c_n0_mol_m3=None,
              c_p0_mol_m3=None, temperature_k, sets: ParameterSets | None = None, backend: str = "auto",
              keep_states: bool = False, initial_state: tuple[np.ndarray, np.ndarray] | None = None) -> CellRuns:
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
        Cell temperature in K (isothermal), scalar or (n_sets,).
    sets : ParameterSets, optional
        Cells that differ from the built one; None runs the built cell.
    backend : str
        ``"auto"`` (the fused Numba kernel when available), ``"numba"`` or ``"numpy"``.
    keep_states : bool
        Keep the modal state at every step boundary (for :func:`voltages_at_times`); this runs the
        recurrence and the voltage in two passes.

    Returns
    -------
    CellRuns
        ``extra["backend"]`` names the path that ran: ``"numba-fused"``, ``"numba"`` or ``"numpy"``.
    """
    duration_s = np.asarray(duration_s, dtype=float)
    current = np.asarray(cell_current_a, dtype=float)
    if duration_s.ndim != 1 or duration_s.shape != current.shape or duration_s.size == 0:
        raise SimulationError("steps: durations and currents must be 1-D of equal non-zero length")
    if not (np.all(np.isfinite(duration_s)) and np.all(duration_s > 0) and np.all(np.isfinite(current))):
        raise SimulationError("steps: durations must be finite and > 0 s, currents finite")
    if backend not in ("auto", "numba", "numpy"):
        raise SimulationError(f"unknown engine backend '{backend}' (auto, numba or numpy)")
    sets = sets or ParameterSets()
    if (initial_state is None) == (c_n0_mol_m3 is None or c_p0_mol_m3 is None):
        raise SimulationError("give either both initial concentrations or an initial state")
    n_state_sets = 1 if initial_state is None else max(np.atleast_2d(y).shape[0] for y in initial_state)
    n_sets = max(sets.size(), np.size(c_n0_mol_m3), np.size(c_p0_mol_m3), np.size(temperature_k), n_state_sets)
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


def _run_fused(kernel, model: LinearSpm, modal: ModalSystem, batch: _Batch, z0: np.ndarray, duration_s: np.ndarray,
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
    high = (np.nan_to_num(start_v, nan=0.0) > MAX_CELL_VOLTAGE_V) | (np.nan_to_num(end_v, nan=0.0) > MAX_CELL_VOLTAGE_V)
    if high.any():
        step = int(np.argmax(high.any(axis=0)))
        raise SimulationError(f"the cell was charged past full at {edges[step]:.0f} s (the model's voltage left "
                              f"its range, above {MAX_CELL_VOLTAGE_V:.0f} V): the initial state is too high for "
                              "the charge that follows")


def _run_two_pass(model: LinearSpm, modal: ModalSystem, batch: _Batch, z0: np.ndarray, duration_s: np.ndarray,
                  current: np.ndarray, edges: np.ndarray, backend: str, stride: int) -> CellRuns:
    """States at every boundary (Numba or NumPy recurrence), then the voltage on all of them (NumPy)."""
    n_sets = z0.shape[0]
    surfaces, checkpoints, z_end = boundary_surfaces(batch.lam, batch.drive, z0, duration_s, current,
                                                     modal.surface_weights, stride=stride, backend=backend)
    start_v = _voltage(model, batch, surfaces[:, :-1], current[None, :])
    end_v = _voltage(model, batch, surfaces[:, 1:], current[None, :])
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
        tau = _cutoff_in_step(model, modal, _take(batch, inside), z_k, duration_s[cutoff_step[inside]],
                              current[cutoff_step[inside]])
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
             "batch": batch, "backend": used, "surfaces": surfaces}
    return CellRuns(step_start_s=edges[:-1], start_voltage_v=start_v, end_voltage_v=end_v, end_time_s=end_time,
                    reached_cutoff=any_below, cutoff_step=cutoff_step, final_state=modal.block_states(z_final),
                    extra=extra)


def _take(batch: _Batch, idx: np.ndarray) -> _Batch:
    return _Batch(*(getattr(batch, name)[idx] for name in batch.__dataclass_fields__))


def _within_step(modal: ModalSystem, batch: _Batch, z_k: np.ndarray, tau_s: np.ndarray, current_a: np.ndarray):
    """Surface values (n, 2) at ``tau_s`` into the step from modal states ``z_k`` (n, n_modes)."""
    decay, phi = step_coefficients(batch.lam, tau_s[:, None])
    z = decay * z_k + phi * batch.drive * current_a[:, None]
    return z @ modal.surface_weights.T


def _cutoff_in_step(model: LinearSpm, modal: ModalSystem, batch: _Batch, z_k: np.ndarray, h_s: np.ndarray,
                    current_a: np.ndarray) -> np.ndarray:
    """Time into the step (s) at which the voltage meets the cut-off (Illinois regula falsi, vectorised)."""
    cut = model.lower_cutoff_v

    def f(tau):
        s = _within_step(modal, batch, z_k, tau, current_a)
        return model.cell_voltage_v(s[:, 0], s[:, 1], current_a, batch.temperature_k, batch.eps_n, batch.eps_p,
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


def states_at_times(runs: CellRuns, modal: ModalSystem, duration_s, cell_current_a, time_s) -> np.ndarray:
    """Surface values (n_sets, n_times, 2) at ``time_s`` (right-continuous), from a run that kept its states."""
    if runs.extra.get("stride") != 1:
        raise SimulationError("states at arbitrary times need a run that kept every state (keep_states=True)")
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


def voltages_at_times(model: LinearSpm, runs: CellRuns, modal: ModalSystem, duration_s, cell_current_a,
                      time_s) -> np.ndarray:
    """Cell voltage (V, n_sets x n_times) at ``time_s`` under the current in force there (right-continuous).

    Times on a step start reuse the run's start voltages; the others are stepped into their step.
    """
    time_s = np.asarray(time_s, dtype=float)
    current = np.asarray(cell_current_a, dtype=float)
    step = np.clip(np.searchsorted(runs.step_start_s, time_s, side="right") - 1, 0, np.size(duration_s) - 1)
    on_start = time_s == runs.step_start_s[step]
    out = runs.start_voltage_v[:, step].copy()
    inside = np.nonzero(~on_start | np.isnan(out).any(axis=0))[0]
    if inside.size:
        surfaces = states_at_times(runs, modal, duration_s, current, time_s[inside])
        out[:, inside] = _voltage(model, runs.extra["batch"], surfaces, current[step[inside]][None, :])
    return out
