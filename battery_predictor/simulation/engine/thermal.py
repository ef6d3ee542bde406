"""The lumped thermal cell in the engine: temperature as one more state, stepped with the particles.

A cell built with PyBaMM's option ``{"thermal": "lumped"}`` has one temperature ``T`` (K) that
obeys PyBaMM's own heat equation (:class:`~battery_predictor.simulation.engine.model.LumpedThermal`):

    rho c_p V dT/dt = Q(s_n, s_p, I, T) - h A (T - T_amb)

with PyBaMM's heat sources of the SPM (reaction heat ``I eta``, which is ``I (U_ocv - V)`` of the
cell, reversible entropic heat ``I T dU/dT`` where the parameter set has an entropic change,
current-collector Ohmic heat, contact-resistance heat with that option), its volume-averaged
heat capacity, total heat transfer coefficient and cooling surface, all from the params'
parameter values. The temperature enters the voltage (exchange currents, OCPs) through PyBaMM's
voltage expression and the particles through their diffusivities.

Stepping (:func:`thermal_recurrence`): within a step of length ``h`` under the current ``I`` the
particles are stepped exactly (modal zero-order hold) with their diffusivities at the step's
predicted mid-temperature ``T_k + h/2 f(s_k, I, T_k)`` (eigenvalues ``lam g(T)``, ``g`` the
diffusivity over its value at the ambient temperature), then the temperature by Heun's method
(explicit trapezoid) on PyBaMM's heat equation,
``T_{k+1} = T_k + h/2 (f(s_k, I, T_k) + f(s_{k+1}, I, T_k + h f(s_k, I, T_k)))``.
Steps longer than :data:`MAX_THERMAL_STEP_S` are split into equal sub-steps (exact for the
particles, a shorter step for the temperature). Inside a step (reports between step starts, the
state at a cut-off) the temperature is Heun's step of that length from the step's start; the
cut-off root itself follows the temperature's Euler line through the step. The error against
PyBaMM's solver is measured in ``test/unit/test_engine_thermal.py`` (figures in BENCHMARKS.md).

``g(T)`` is the params' diffusivity function evaluated by PyBaMM on a grid uniform in ``1/T``
and interpolated linearly in ``(1/T, ln g)``, which is exact for Arrhenius laws; constant
diffusivities (Chen2020, Prada2013) skip it.

The recurrence runs in a compiled kernel (Numba; the heat equation and the voltage printed by
PyBaMM as in :mod:`~battery_predictor.simulation.engine.kernel`; the voltage at every step start and
end, each set stopped at its first voltage below the cut-off) or in NumPy (a loop over steps
vectorised over the sets, PyBaMM's generated NumPy code for the heat equation, the voltage
afterwards on every boundary; about 200x slower, the path for machines without Numba).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.engine.kernel import Kernel, forget_thermal_kernel, thermal_kernel
from battery_predictor.simulation.engine.modal import step_coefficients

if TYPE_CHECKING:
    import pybamm

    from battery_predictor.simulation.engine.modal import ModalSystem
    from battery_predictor.simulation.engine.model import LinearSpm

LOG = logging.getLogger(__name__)
#: Longest step (s) the temperature is advanced in one go; longer steps are split.
MAX_THERMAL_STEP_S = 10.0
#: Cell temperatures (K) the diffusivity table covers; a run that leaves them raises.
TABLE_RANGE_K = (180.0, 480.0)
_TABLE_POINTS = 2049


@dataclass(frozen=True)
class DiffusivityTemperature:
    """Particle diffusivities' temperature dependence as ``ln g_e`` on a grid uniform in ``1/T``.

    Attributes
    ----------
    inverse_start_per_k : float
        First grid point of ``1/T`` (1/K).
    inverse_step_per_k : float
        Grid spacing of ``1/T`` (1/K).
    ln_factor : numpy.ndarray
        ``ln(D_e(T) / D_e(T_0))`` per electrode (negative, positive), shape (2, n_grid), ``T_0``
        the temperature the run's diffusivity factors refer to.
    constant : bool
        True when neither diffusivity depends on the temperature.
    """

    inverse_start_per_k: float
    inverse_step_per_k: float
    ln_factor: np.ndarray
    constant: bool

    def factors(self, temperature_k: npt.ArrayLike) -> np.ndarray:
        """``g_e(T)`` per electrode, shape (..., 2)."""
        t = np.asarray(temperature_k, dtype=float)
        if self.constant:
            return np.ones(t.shape + (2,))
        x = (1.0 / t - self.inverse_start_per_k) / self.inverse_step_per_k
        j = np.clip(np.floor(x).astype(int), 0, self.ln_factor.shape[1] - 2)
        frac = x - j
        ln_g = self.ln_factor[:, j] * (1.0 - frac) + self.ln_factor[:, j + 1] * frac
        return np.exp(np.moveaxis(ln_g, 0, -1))


def diffusivity_temperature(pv: pybamm.ParameterValues, keys: tuple[str, str], reference_temperature_k: float) -> DiffusivityTemperature:
    """The table of ``pv``'s diffusivities (``keys``: negative, positive) relative to ``reference_temperature_k``.

    Functions are evaluated by PyBaMM at stoichiometry 0.5 and must not depend on it at any of the
    table's temperatures (:data:`~battery_predictor.simulation.engine.model.STOICHIOMETRY_PROBES`).
    """
    import pybamm

    from battery_predictor.simulation.engine.model import STOICHIOMETRY_PROBES, require_constant_in_stoichiometry

    lo, hi = TABLE_RANGE_K
    inverse = np.linspace(1.0 / hi, 1.0 / lo, _TABLE_POINTS)
    rows = []
    for key in keys:
        value = pv[key]
        if isinstance(value, (int, float)):
            rows.append(np.zeros(inverse.size))
            continue
        try:
            probes = [np.broadcast_to(np.asarray(pv.evaluate(value(pybamm.Scalar(x), pybamm.Vector(1.0 / inverse))),
                                             dtype=float).ravel(), inverse.shape) for x in STOICHIOMETRY_PROBES]
            require_constant_in_stoichiometry(key, np.vstack(probes), f"between {lo:.0f} and {hi:.0f} K")
            grid = probes[1]
            ref = float(np.asarray(pv.evaluate(value(pybamm.Scalar(0.5), pybamm.Scalar(reference_temperature_k))))
                        .ravel()[0])
        except (KeyError, ValueError, TypeError, NotImplementedError) as exc:
            raise SimulationError(f"cannot evaluate '{key}' over the temperature: {str(exc).splitlines()[0]}") from None
        grid = np.broadcast_to(grid, inverse.shape)
        if not (np.all(np.isfinite(grid)) and np.all(grid > 0.0) and ref > 0.0):
            raise SimulationError(f"'{key}' is not positive and finite over {lo:.0f}..{hi:.0f} K")
        rows.append(np.log(grid / ref))
    ln_factor = np.vstack(rows)
    return DiffusivityTemperature(inverse_start_per_k=float(inverse[0]),
                                  inverse_step_per_k=float(inverse[1] - inverse[0]), ln_factor=ln_factor,
                                  constant=bool(np.all(ln_factor == 0.0)))


@dataclass(frozen=True)
class HeatCapacity:
    """PyBaMM's volume-averaged heat capacity as a function of the electrode thicknesses.

    ``rho c_p = (C_0 + c_n L_n + c_p L_p) / (L_0 + L_n + L_p)`` (PyBaMM's ``rho_c_p_eff``: the layers'
    heat capacities weighted by their thickness), at one temperature.

    Attributes
    ----------
    other_j_m2_k : float
        ``C_0``: current collectors and separator (J/(m2 K)).
    other_m : float
        ``L_0``: their thickness (m).
    negative_j_m3_k, positive_j_m3_k : float
        ``c_n``, ``c_p``: the electrodes' volumetric heat capacities (J/(m3 K)).
    """

    other_j_m2_k: float
    other_m: float
    negative_j_m3_k: float
    positive_j_m3_k: float

    def j_m3_k(self, thickness_n_m: npt.ArrayLike, thickness_p_m: npt.ArrayLike) -> np.ndarray:
        """Volume-averaged heat capacity (J/(m3 K)) at electrode thicknesses (m)."""
        l_n, l_p = np.asarray(thickness_n_m, dtype=float), np.asarray(thickness_p_m, dtype=float)
        return (self.other_j_m2_k + self.negative_j_m3_k * l_n + self.positive_j_m3_k * l_p) / (
            self.other_m + l_n + l_p)


def heat_capacity(pv: pybamm.ParameterValues, temperature_k: float) -> HeatCapacity:
    """:class:`HeatCapacity` of parameter values ``pv`` at ``temperature_k`` (K), evaluated by PyBaMM."""
    import pybamm

    thermal, geometry = pybamm.ThermalParameters(), pybamm.GeometricParameters()
    t = pybamm.Scalar(float(temperature_k))

    def value(symbol: pybamm.Symbol) -> float:
        return float(np.asarray(pv.evaluate(symbol)).ravel()[0])

    try:
        l_n, l_p, l_total = value(geometry.n.L), value(geometry.p.L), value(geometry.L)
        c_n, c_p = value(thermal.n.rho_c_p(t)), value(thermal.p.rho_c_p(t))
        total = value(thermal.rho_c_p_eff(t)) * l_total
    except (KeyError, ValueError, TypeError) as exc:
        raise SimulationError(f"cannot evaluate the cell's heat capacity: {str(exc).splitlines()[0]}") from None
    return HeatCapacity(other_j_m2_k=total - c_n * l_n - c_p * l_p, other_m=l_total - l_n - l_p,
                        negative_j_m3_k=c_n, positive_j_m3_k=c_p)


def split_steps(duration_s: np.ndarray, max_step_s: float = MAX_THERMAL_STEP_S) -> np.ndarray:
    """Number of equal sub-steps of each step so that none is longer than ``max_step_s``."""
    return np.maximum(1, np.ceil(duration_s / max_step_s - 1e-12)).astype(np.int64)


@dataclass
class ThermalTrace:
    """Boundary values of a thermal recurrence on (sub-)steps.

    Attributes
    ----------
    surfaces : numpy.ndarray
        Surface stoichiometries at every boundary, (n_sets, n_steps + 1, 2).
    temperature_k : numpy.ndarray
        Cell temperature (K) at every boundary, (n_sets, n_steps + 1).
    diffusivity_factor : numpy.ndarray
        ``g_e(T_k)`` the particles were stepped with, (n_sets, n_steps, 2).
    states : numpy.ndarray
        Modal states at boundaries ``0, stride, 2 stride, ...``, (n_sets, n_steps // stride + 1, n_modes).
    stride : int
        Boundaries between kept states.
    z_end : numpy.ndarray
        Modal states at the end, (n_sets, n_modes).
    backend : str
        ``"numba"`` or ``"numpy"``.
    voltages_v : tuple of numpy.ndarray or None
        Cell voltage (V) at every step start and end under the step's current, (n_sets, n_steps)
        each, when the compiled kernel evaluated them (else the caller evaluates the voltage). The
        kernel stops a set at the first voltage below the cut-off: its later voltages, surfaces and
        temperatures are NaN (and its kept states and ``z_end`` stop there too).
    """

    surfaces: np.ndarray
    temperature_k: np.ndarray
    diffusivity_factor: np.ndarray
    states: np.ndarray
    stride: int
    z_end: np.ndarray
    backend: str
    voltages_v: tuple[np.ndarray, np.ndarray] | None = None

    def states_at(self, lam: np.ndarray, drive: np.ndarray, duration_s: np.ndarray, current_a: np.ndarray,
                  electrode_factors: Callable[[np.ndarray, np.ndarray], np.ndarray], step: np.ndarray) -> np.ndarray:
        """Modal states (n_sets, n_modes) at the start of ``step`` (one index per set), replayed from the kept ones."""
        sets = np.arange(self.states.shape[0])
        z = self.states[sets, step // self.stride].copy()
        first = (step // self.stride) * self.stride
        for k in range(int((step - first).max(initial=0))):
            k_step = np.minimum(first + k, duration_s.size - 1)
            active = first + k < step
            g = self.diffusivity_factor[sets, k_step]
            decay, phi = step_coefficients(lam * electrode_factors(g[:, 0], g[:, 1]), duration_s[k_step][:, None])
            advanced = decay * z + phi * drive * current_a[k_step][:, None]
            z = np.where(active[:, None], advanced, z)
        return z


def thermal_recurrence(model: LinearSpm, modal: ModalSystem, lam: np.ndarray, drive: np.ndarray, z0: np.ndarray, temperature0_k: np.ndarray,
                       ambient_k: np.ndarray, eps_n: np.ndarray, eps_p: np.ndarray, height_m: np.ndarray,
                       duration_s: np.ndarray, current_a: np.ndarray, table: DiffusivityTemperature, *,
                       heat_rate: np.ndarray | None = None, stride: int = 64, backend: str = "auto") -> ThermalTrace:
    """Particles and temperature over constant-current steps (see module docstring).

    Parameters
    ----------
    model, modal : LinearSpm, ModalSystem
        The extracted thermal cell (``model.thermal`` set) and its modal form.
    lam, drive : numpy.ndarray
        Eigenvalues (1/s) at the reference temperature of ``table`` and modal inputs (1/(A s)), (n_sets, n_modes).
    z0 : numpy.ndarray
        Initial modal states, (n_sets, n_modes).
    temperature0_k, ambient_k : numpy.ndarray
        Initial cell and ambient temperatures (K), (n_sets,).
    eps_n, eps_p, height_m : numpy.ndarray
        The voltage's (equivalent) volume fractions and electrode height (m), (n_sets,).
    duration_s, current_a : numpy.ndarray
        Step lengths (s) and cell currents (A), (n_steps,).
    table : DiffusivityTemperature
        The diffusivities' temperature dependence.
    heat_rate : numpy.ndarray, optional
        Factor on ``dT/dt`` per set, (n_sets,): the built cell's heat capacity over the set's
        (electrode thicknesses that differ from the built ones); None is 1.
    stride : int
        Keep the modal state every ``stride`` boundaries (1: all).
    backend : str
        ``"auto"`` (compiled when Numba is installed and the heat equation prints), ``"numba"``, ``"numpy"``.
    """
    heat_rate = np.ones(z0.shape[0]) if heat_rate is None else np.broadcast_to(np.asarray(heat_rate, dtype=float),
                                                                               (z0.shape[0],))
    kernel = None
    if backend != "numpy":
        kernel = thermal_kernel(model, parallel=z0.shape[0] >= 64)
        if kernel is None:
            if backend == "numba":
                raise SimulationError("the numba backend was asked for but the heat equation has no compiled form "
                                      "(or numba is not installed)")
            LOG.info("engine: the lumped thermal cell runs on the NumPy path (no compiled form of its heat equation)")
    if kernel is not None:
        from numba.core.errors import NumbaError

        try:
            return _recurrence_numba(kernel, modal, lam, drive, z0, temperature0_k, ambient_k, eps_n, eps_p, height_m,
                                     duration_s, current_a, table, stride, heat_rate, model.lower_cutoff_v)
        except NumbaError as exc:
            LOG.warning("engine: the thermal kernel does not compile for this model (%s); using NumPy",
                        str(exc).splitlines()[0])
            forget_thermal_kernel(model)
    return _recurrence_numpy(model, modal, lam, drive, z0, temperature0_k, ambient_k, eps_n, eps_p, height_m,
                             duration_s, current_a, table, stride, heat_rate)


def _recurrence_numpy(model: LinearSpm, modal: ModalSystem, lam: np.ndarray, drive: np.ndarray, z0: np.ndarray,
                      temperature0_k: np.ndarray, ambient_k: np.ndarray, eps_n: np.ndarray, eps_p: np.ndarray,
                      height_m: np.ndarray, duration_s: np.ndarray, current_a: np.ndarray,
                      table: DiffusivityTemperature, stride: int, heat_rate: np.ndarray) -> ThermalTrace:
    n_sets, n_modes = z0.shape
    n_steps = duration_s.size
    weights = modal.surface_weights
    thermal = model.thermal
    assert thermal is not None  # a thermal run

    def rate(*args: npt.ArrayLike) -> np.ndarray:
        return heat_rate * thermal.temperature_rate_k_s(*args)

    surfaces = np.empty((n_sets, n_steps + 1, 2))
    temps = np.empty((n_sets, n_steps + 1))
    factors = np.empty((n_sets, n_steps, 2))
    states = np.empty((n_sets, n_steps // stride + 1, n_modes))
    z = z0.copy()
    t = np.asarray(temperature0_k, dtype=float).copy()
    s = z @ weights.T
    surfaces[:, 0], temps[:, 0] = s, t
    states[:, 0] = z
    last_h, decay, phid = np.nan, None, None
    for k in range(n_steps):
        h, i = duration_s[k], current_a[k]
        r0 = rate(s[:, 0], s[:, 1], i, t, ambient_k, eps_n, eps_p, height_m)
        if table.constant:
            g = np.ones((n_sets, 2))
            if h != last_h:
                decay, phi = step_coefficients(lam, h)
                phid = phi * drive
                last_h = h
        else:
            g = table.factors(t + 0.5 * h * r0)  # at the step's (predicted) mid-temperature
            decay, phi = step_coefficients(lam * modal.electrode_factors(g[:, 0], g[:, 1]), h)
            phid = phi * drive
        factors[:, k] = g
        z = decay * z + phid * i
        s = z @ weights.T
        r1 = rate(s[:, 0], s[:, 1], i, t + h * r0, ambient_k, eps_n, eps_p, height_m)
        t = t + 0.5 * h * (r0 + r1)
        surfaces[:, k + 1], temps[:, k + 1] = s, t
        if (k + 1) % stride == 0:
            states[:, (k + 1) // stride] = z
    return ThermalTrace(surfaces=surfaces, temperature_k=temps, diffusivity_factor=factors, states=states,
                        stride=stride, z_end=z, backend="numpy")


def _recurrence_numba(kernel: tuple[Kernel, bool], modal: ModalSystem, lam: np.ndarray, drive: np.ndarray,
                      z0: np.ndarray, temperature0_k: np.ndarray, ambient_k: np.ndarray, eps_n: np.ndarray,
                      eps_p: np.ndarray, height_m: np.ndarray, duration_s: np.ndarray, current_a: np.ndarray,
                      table: DiffusivityTemperature, stride: int, heat_rate: np.ndarray,
                      cutoff_v: float) -> ThermalTrace:
    n_sets, n_modes = z0.shape
    n_steps = duration_s.size
    surfaces = np.empty((n_sets, n_steps + 1, 2))
    temps = np.empty((n_sets, n_steps + 1))
    factors = np.empty((n_sets, n_steps, 2))
    states = np.empty((n_sets, n_steps // stride + 1, n_modes))
    z_end = np.empty((n_sets, n_modes))
    compiled, has_voltage = kernel
    start_v = np.empty((n_sets, n_steps)) if has_voltage else np.empty((1, 1))
    end_v = np.empty((n_sets, n_steps)) if has_voltage else np.empty((1, 1))
    c = np.ascontiguousarray
    compiled(c(lam), c(drive), c(z0), c(np.asarray(temperature0_k, dtype=float)), c(np.asarray(ambient_k, dtype=float)),
           c(eps_n), c(eps_p), c(height_m), c(heat_rate), c(duration_s), c(current_a), c(modal.surface_weights),
           int(modal.n_negative), table.inverse_start_per_k, table.inverse_step_per_k, c(table.ln_factor), bool(table.constant),
           int(stride), surfaces, temps, factors, states, z_end, start_v, end_v, float(cutoff_v))
    voltages = (start_v, end_v) if has_voltage else None
    return ThermalTrace(surfaces=surfaces, temperature_k=temps, diffusivity_factor=factors, states=states,
                        stride=stride, z_end=z_end, backend="numba", voltages_v=voltages)
