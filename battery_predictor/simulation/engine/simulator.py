"""The engine behind the pack-simulator interface (:class:`~battery_predictor.simulation.base.PackSimulator`).

A pack of identical cells as in the fast simulator (the cell carries ``I_pack / parallel``, the
pack voltage is :func:`~battery_predictor.simulation.engine.pack.pack_voltage_v`, the cell's lower
cut-off ends the run, voltages are right-continuous at the report times), with the cell stepped
by the engine. Cells that differ from a built one only in particle radii, diffusivities,
electrode thicknesses, active material volume fractions, electrode height, initial concentrations
and (where a PyBaMM rebuild confirms the rule once per model structure) maximum concentrations
reuse its extraction (scaling, no PyBaMM rebuild).

Diffusivities that depend on the temperature only (PyBaMM functions, e.g. NCA_Kim2011) are taken at
the request's temperature. Params with the PyBaMM option ``{"thermal": "lumped"}`` (``cell.options``)
run a lumped thermal cell (:mod:`~battery_predictor.simulation.engine.thermal`): the request's
temperature is the ambient one and the cell's initial one, the result carries the cell
temperature at the report times (``extra["cell_temperature_k"]``) and ``extra["thermal"]``; electrode
thicknesses scale the cell's heat capacity as PyBaMM's volume average of the layers does
(``ParameterSets.heat_rate``). What the engine does not cover (models other than the SPM, the
extensions outside :data:`ENGINE_EXTENSIONS`, model options or states that the voltage
depends on beyond the particle surfaces, concentration-dependent diffusivities, per-cell values)
is simulated by the fallback simulator (the fast one by default); the result says so in
``extra["engine_fallback"]`` and a warning is logged, so a fallback is never silent.

The extension ``cell_imbalance`` runs its weak series group as a second parameter set of the same
extraction (electrode height x the weak fraction, the same initial concentrations): the pack voltage
is ``(series - 1) V_normal + V_weak - I R_eq`` and the run ends with the group that reaches the
cut-off first Every result carries each group's cell terminal voltage at the report times
(``extra["group_cell_voltage_v"]``, shape (groups, times): the normal cells', then the weak group's).

The extension ``hysteresis`` (PyBaMM's one-state Axen OCP hysteresis) runs on isothermal cells: the cell
is extracted without the option and the hysteresis voltage is stepped exactly beside it
(:mod:`~battery_predictor.simulation.engine.hysteresis`); the result carries ``extra["hysteresis_state"]``
at the report times. With a lumped thermal cell, or in :meth:`EngineSimulator.simulate_batch`, it is
not covered (fallback, or an error for the batch).
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.base import PackSimResult, PackSimulator, SimulationRequest
from battery_predictor.simulation.cell_setup import is_lumped_thermal, prepared_parameter_values
from battery_predictor.simulation.engine.modal import ModalSystem, modal_system
from battery_predictor.simulation.engine.model import (
    C_MAX_N,
    C_MAX_P,
    C_N0,
    C_P0,
    EPS_N,
    EPS_P,
    HEIGHT,
    LinearSpm,
    c_max_scaling_holds,
    diffusivity_m2_s,
    extract_linear_spm,
)
from battery_predictor.simulation.engine.pack import pack_voltage_v
from battery_predictor.simulation.engine.run import (
    CellRuns,
    ParameterSets,
    run_cells,
    temperatures_at_times,
    voltages_at_times,
)
from battery_predictor.simulation.engine.state import StoichiometryWindow
from battery_predictor.simulation.engine.thermal import (
    DiffusivityTemperature,
    HeatCapacity,
    diffusivity_temperature,
    heat_capacity,
)
from battery_predictor.simulation.extensions import (
    COLD_ANCHOR_KEYS,
    HYS_ACTIVATION,
    HYS_DECAY,
    HYS_HALF_WIDTH,
    HYS_INITIAL,
    HYS_RELAX,
    WEAK_FRACTION,
    cold_window_active,
    cold_window_anchors,
    extension_value,
    hysteresis_half_width_v,
    hysteresis_rate_per_c,
    series_resistance_factor,
    weak_group_fraction,
)
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

if TYPE_CHECKING:
    import pybamm

    from battery_predictor.params import PackParams

LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class PackBatchResult:
    """Many cells of one pack structure run on one load.

    Attributes
    ----------
    time_s : numpy.ndarray
        Step start times in s, shape (n_steps,).
    cell_voltage_v : numpy.ndarray
        Cell voltage (V) just after each step start, (n_sets, n_steps); NaN once a run has ended.
    pack_voltage_v : numpy.ndarray
        Pack voltage (V) at the same times (:func:`~battery_predictor.simulation.engine.pack.pack_voltage_v`
        with the params' ``R_eq``).
    end_time_s : numpy.ndarray
        When each run ended (s).
    reached_cutoff : numpy.ndarray
        True where the cell reached its lower cut-off.
    engine_seconds : float
        Wall time of the engine run (s).
    runs : CellRuns
        The engine's own result.
    """

    time_s: np.ndarray
    cell_voltage_v: np.ndarray
    pack_voltage_v: np.ndarray
    end_time_s: np.ndarray
    reached_cutoff: np.ndarray
    engine_seconds: float
    runs: CellRuns

#: Cell values a built extraction can take by scaling: PyBaMM key -> ParameterSets field.
SCALABLE_KEYS = {
    "Negative particle radius [m]": "radius_n",
    "Positive particle radius [m]": "radius_p",
    "Negative particle diffusivity [m2.s-1]": "diffusivity_n",
    "Positive particle diffusivity [m2.s-1]": "diffusivity_p",
    "Negative electrode thickness [m]": "thickness_n",
    "Positive electrode thickness [m]": "thickness_p",
    EPS_N: "fraction_n",
    EPS_P: "fraction_p",
    HEIGHT: "height",
}
DIFFUSIVITY_KEYS = ("Negative particle diffusivity [m2.s-1]", "Positive particle diffusivity [m2.s-1]")
THICKNESS_KEYS = ("Negative electrode thickness [m]", "Positive electrode thickness [m]")
#: Temperatures (K) at which diffusivities are compared to reuse a table of their temperature dependence.
_SIGNATURE_K = (233.15, 263.15, 298.15, 333.15, 373.15)

#: The maximum concentrations, scalable where :func:`c_max_scaling_holds`.
C_MAX_KEYS = {C_MAX_N: "c_max_n", C_MAX_P: "c_max_p"}
_STATE_KEYS = frozenset({C_N0, C_P0})
#: Values of the extensions run beside the cell (the extraction does not depend on them).
_BESIDE_KEYS = frozenset({HYS_HALF_WIDTH, HYS_DECAY, HYS_INITIAL, HYS_RELAX, HYS_ACTIVATION, WEAK_FRACTION})
#: Extensions whose whole effect is inside PyBaMM's cell model (model options, parameter values) or
#: outside the simulator (the current offset is applied where a recording becomes a load); the
#: extraction checks that the model still splits into linear particles and a voltage function.
CELL_MODEL_EXTENSIONS = ("capacity_fade", "current_offset", "hysteresis", "resistance_growth")
#: Extensions the simulator covers: the cell-model ones, ``temperature`` (its diffusivities and
#: exchange currents are inside PyBaMM's model; its series-resistance factor is applied to ``R_eq``
#: at the cell temperature, :func:`_series_resistance_ohm`) and ``cell_imbalance`` (the weak group is
#: a second parameter set of the same extraction, its electrode height scaled).
ENGINE_EXTENSIONS = CELL_MODEL_EXTENSIONS + ("temperature", "cell_imbalance")
#: Extensions the simulator runs beside the extracted cell (the cell is extracted without them).
VOLTAGE_TERM_EXTENSIONS = ("hysteresis", "cell_imbalance")


def engine_cell_params(params: PackParams) -> PackParams:
    """``params`` without the extensions the engine steps beside the cell (:data:`VOLTAGE_TERM_EXTENSIONS`)."""
    kept = tuple(e for e in params.extensions if e not in VOLTAGE_TERM_EXTENSIONS)
    return params if kept == tuple(params.extensions) else replace(params, extensions=kept)


def _series_resistance_ohm(params: PackParams, temperature_k: npt.ArrayLike) -> np.ndarray:
    """The pack's ``R_eq`` (Ohm) at cell temperatures ``temperature_k`` (K): the extension ``temperature``'s
    Arrhenius factor (:func:`~battery_predictor.simulation.extensions.series_resistance_factor`), else constant."""
    p = params.interconnect
    r_eq = equivalent_network_resistance_ohm(params.series, params.parallel, p["r_b_ohm"], p["r_c_ohm"], p["r_t_ohm"])
    if "temperature" not in params.extensions:
        return np.asarray(r_eq, dtype=float)
    return r_eq * series_resistance_factor(params, temperature_k)


#: :func:`_diffusivity_reason` by (params fingerprint, extensions, options, temperature).
_DIFFUSIVITY_REASONS: dict[tuple, str | None] = {}


def _diffusivity_reason(params: PackParams, temperature_k: float) -> str | None:
    """Why the params' particle diffusivities keep the engine out (they depend on the stoichiometry at
    ``temperature_k`` (K), or anywhere in the thermal table's range for a lumped thermal cell), else None.

    Cached: the check builds PyBaMM's parameter values (~10 ms) and evaluates the diffusivity functions.
    """
    key = (params.fingerprint(), tuple(params.extensions), repr(sorted(params.options.items())), float(temperature_k))
    if key not in _DIFFUSIVITY_REASONS:
        if len(_DIFFUSIVITY_REASONS) >= 256:
            _DIFFUSIVITY_REASONS.clear()
        pv = prepared_parameter_values(params)
        try:
            if is_lumped_thermal(params):
                diffusivity_temperature(pv, DIFFUSIVITY_KEYS, float(temperature_k))
            else:
                for pybamm_key in DIFFUSIVITY_KEYS:
                    diffusivity_m2_s(pv, pybamm_key, float(temperature_k))
            _DIFFUSIVITY_REASONS[key] = None
        except SimulationError as exc:
            _DIFFUSIVITY_REASONS[key] = str(exc)
    return _DIFFUSIVITY_REASONS[key]


class EngineSimulator:
    """Pack simulator on the SPM engine (see module docstring).

    Parameters
    ----------
    backend : str
        Recurrence backend: ``"auto"`` (Numba when installed), ``"numba"`` or ``"numpy"``.
    fallback : object, "fast" or None
        Simulator for what the engine does not cover (``"fast"``: a
        :class:`~battery_predictor.simulation.fast.FastPackSimulator`); None raises instead.
    cache_size : int
        Extracted models kept.
    """

    name = "engine"

    def __init__(self, backend: str = "auto", fallback: PackSimulator | Literal["fast"] | None = "fast",
                 cache_size: int = 8) -> None:
        self.fallback: PackSimulator | None
        if fallback == "fast":
            from battery_predictor.simulation.fast import FastPackSimulator

            self.fallback = FastPackSimulator()
        else:
            self.fallback = fallback
        self.backend = backend
        self.cache_size = cache_size
        self._cache: OrderedDict[tuple, tuple[LinearSpm, ModalSystem]] = OrderedDict()
        self._values: dict[tuple, object] = {}
        self._c_max_rule: dict[tuple, bool] = {}
        self._tables: OrderedDict[tuple, DiffusivityTemperature] = OrderedDict()
        self._heat_capacities: dict[tuple, HeatCapacity] = {}
        self.extractions = 0

    # ----------------------------------------------------------------- public
    def simulate(self, params: PackParams, request: SimulationRequest) -> PackSimResult:
        """Simulate ``request`` on the pack ``params``; see :class:`PackSimulator`."""
        tic = time.perf_counter()
        reason = self.unsupported_reason(params, request)
        if reason is None:
            try:
                model, modal, sets = self._model(params, self._temperature_k(params, request))
            except SimulationError as exc:
                reason = str(exc)
        if reason is not None:
            return self._fall_back(params, request, reason)
        return self._simulate(params, request, model, modal, sets, tic)

    def simulate_batch(self, params: PackParams, request: SimulationRequest, values: dict[str, np.ndarray]) -> PackBatchResult:
        """Run many variants of ``params`` on ``request`` at once (no fallback: raises when not covered).

        Parameters
        ----------
        params : PackParams
            The pack; its values are the defaults of every set.
        request : SimulationRequest
            Load, temperature and initial state. The initial state of each set is its
            ``values`` of the initial concentrations when given, else the request's SOC or open-circuit
            voltage (a window per set: about 5 ms each), else the params' concentrations.
        values : dict
            PyBaMM key -> array of shape (n_sets,): any of :data:`SCALABLE_KEYS` and the initial
            concentrations.

        Returns
        -------
        PackBatchResult
        """
        reason = self.unsupported_reason(params, request)
        if reason is None and "hysteresis" in params.extensions:
            reason = "the batch does not run the hysteresis extension (simulate each set)"
        if reason is None and weak_group_fraction(params) != 1.0:
            reason = "the batch does not run a weak series group (simulate each set)"
        if reason is not None:
            raise SimulationError(f"engine: {reason}")
        model, modal, base = self._model(params, self._temperature_k(params, request))
        n_sets = max((np.size(v) for v in values.values()), default=1)
        factors = self._batch_factors(params, model, base, values, self._temperature_k(params, request))
        c_n0, c_p0 = self._batch_concentrations(params, request, model, values, n_sets)
        load = request.load
        duration_s = np.diff(load.edges_s())
        cell_current_a = load.current_a / params.parallel
        tic = time.perf_counter()
        temperature_k = self._temperature_k(params, request)
        runs = run_cells(model, modal, duration_s, cell_current_a, c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                         temperature_k=temperature_k, sets=ParameterSets(**factors), backend=self.backend,
                         diffusivity_temperature=self._diffusivity_table(params, model, temperature_k))
        engine_s = time.perf_counter() - tic
        cell_temperature_k = temperature_k if model.thermal is None else runs.extra["temperature_k"][:, :-1]
        r_eq = _series_resistance_ohm(params, cell_temperature_k)
        v_pack = pack_voltage_v(runs.start_voltage_v, load.current_a[None, :], series=params.series, r_eq_ohm=r_eq)
        return PackBatchResult(time_s=runs.step_start_s, cell_voltage_v=runs.start_voltage_v, pack_voltage_v=v_pack,
                               end_time_s=runs.end_time_s, reached_cutoff=runs.reached_cutoff, engine_seconds=engine_s,
                               runs=runs)

    def _batch_concentrations(self, params: PackParams, request: SimulationRequest, model: LinearSpm, values: dict,
                              n_sets: int) -> tuple[np.ndarray, np.ndarray]:
        if C_N0 in values or C_P0 in values:
            pv = self._parameter_values(params)
            return (np.broadcast_to(np.asarray(values.get(C_N0, pv[C_N0]), dtype=float), (n_sets,)),
                    np.broadcast_to(np.asarray(values.get(C_P0, pv[C_P0]), dtype=float), (n_sets,)))
        if request.initial_soc is None and request.initial_pack_ocv_v is None:
            c_n, c_p = self._initial_concentrations(params, request, model)
            return np.full(n_sets, c_n), np.full(n_sets, c_p)
        pv = self._parameter_values(params)
        out = np.empty((2, n_sets))
        for k in range(n_sets):
            set_pv = _Overlay(pv, {key: float(np.broadcast_to(arr, (n_sets,))[k]) for key, arr in values.items()})
            window = StoichiometryWindow(model, set_pv)
            if request.initial_soc is not None:
                out[:, k] = window.concentrations(soc=float(request.initial_soc))
            else:
                assert request.initial_pack_ocv_v is not None  # one of the two is given (checked by the caller)
                out[:, k] = window.concentrations(ocv_v=float(request.initial_pack_ocv_v) / params.series)
        return out[0], out[1]

    @staticmethod
    def unsupported_reason(params: PackParams, request: SimulationRequest) -> str | None:
        """Why the engine cannot simulate ``request`` on ``params`` (None when it can)."""
        if request.cell_inputs:
            return "per-cell values need liionpack"
        if params.model != "SPM":
            return f"the engine covers the SPM, not the {params.model}"
        outside = sorted(set(params.extensions) - set(ENGINE_EXTENSIONS))
        if outside:
            return f"the engine does not cover the extensions {outside}"
        if "hysteresis" in params.extensions and is_lumped_thermal(params):
            return "the engine's hysteresis extension runs on isothermal cells, not a lumped thermal one"
        if "hysteresis" in params.extensions and weak_group_fraction(params) != 1.0:
            return "the engine runs the hysteresis extension without a weak series group"
        return _diffusivity_reason(params, EngineSimulator._temperature_k(params, request))

    # ---------------------------------------------------------------- helpers
    def _fall_back(self, params: PackParams, request: SimulationRequest, reason: str) -> PackSimResult:
        if self.fallback is None:
            raise SimulationError(f"engine: {reason}")
        LOG.warning("engine: %s; simulating with the %s simulator", reason, self.fallback.name)
        result = self.fallback.simulate(params, request)
        result.extra["engine_fallback"] = f"{self.fallback.name}: {reason}"
        return result

    def _scalable_keys(self, params: PackParams) -> dict[str, str]:
        """:data:`SCALABLE_KEYS`, plus the maximum concentrations where this model structure obeys their rule."""
        params = engine_cell_params(params)
        structure = (params.base_parameter_set, params.model, repr(sorted(params.options.items())), params.extensions)
        if structure not in self._c_max_rule:
            self._c_max_rule[structure] = c_max_scaling_holds(params)
        return {**SCALABLE_KEYS, **C_MAX_KEYS} if self._c_max_rule[structure] else SCALABLE_KEYS

    def _diffusivity_table(self, params: PackParams, model: LinearSpm, temperature_k: float) -> DiffusivityTemperature | None:
        """Thermal cells: the params' diffusivities over the temperature relative to ``temperature_k`` (cached)."""
        if model.thermal is None:
            return None
        pv = self._parameter_values(params)
        signature = tuple(diffusivity_m2_s(pv, key, t) for key in DIFFUSIVITY_KEYS for t in _SIGNATURE_K)
        key = (params.base_parameter_set, signature, float(temperature_k))
        if key not in self._tables:
            self._tables[key] = diffusivity_temperature(pv, DIFFUSIVITY_KEYS, temperature_k)
            if len(self._tables) > self.cache_size:
                self._tables.popitem(last=False)
        return self._tables[key]

    @staticmethod
    def _temperature_k(params: PackParams, request: SimulationRequest) -> float:
        return float(request.ambient_temperature_k or params.ambient_temperature_k)

    def _model(self, params: PackParams, temperature_k: float) -> tuple[LinearSpm, ModalSystem, ParameterSets]:
        """The extraction for ``params`` (cached on everything but scalable values) and its scale factors.

        Diffusivities that are functions of the temperature are taken at ``temperature_k`` (the
        isothermal cell's), as a factor on the extraction's.
        """
        params = engine_cell_params(params)  # the hysteresis runs beside the extracted cell
        values = params.cell_values
        scalable = self._scalable_keys(params)
        fixed = tuple(sorted((k, repr(v)) for k, v in values.items()
                             if k not in scalable and k not in _STATE_KEYS and k not in _BESIDE_KEYS))
        key = (params.base_parameter_set, params.model, repr(sorted(params.options.items())), params.extensions, fixed,
               self._cold_anchors(params))
        if key in self._cache:
            self._cache.move_to_end(key)
            model, modal = self._cache[key]
        else:
            model = extract_linear_spm(params)
            modal = modal_system(model)
            self.extractions += 1
            self._cache[key] = (model, modal)
            if len(self._cache) > self.cache_size:
                self._cache.popitem(last=False)
        pv = self._parameter_values(params)
        factors = {}
        for pybamm_key, field_name in scalable.items():
            if pybamm_key in DIFFUSIVITY_KEYS:
                value = diffusivity_m2_s(pv, pybamm_key, temperature_k)
            else:
                value = pv[pybamm_key]
                if not isinstance(value, (int, float)):
                    raise SimulationError(f"'{pybamm_key}' is not a constant; the engine needs a constant")
            factors[field_name] = float(value) / model.built_values[pybamm_key]
        if model.thermal is not None:
            factors["heat_rate"] = self._heat_rate(model, pv, temperature_k, factors)
        return model, modal, ParameterSets(**factors)

    def _cold_anchors(self, params: PackParams) -> tuple[float, float] | None:
        """The cold window's anchors the extraction bakes in, when they follow the cell's values (part of the cache key)."""
        if not cold_window_active(params) or all(k in params.cell_values for k in COLD_ANCHOR_KEYS):
            return None
        return cold_window_anchors(params, self._parameter_values(params))

    def _heat_rate(self, model: LinearSpm, pv: pybamm.ParameterValues, temperature_k: float,
                   factors: dict) -> np.ndarray:
        """Thermal cells: the built cell's heat capacity over that of the sets' electrode thicknesses."""
        key = (model, float(temperature_k))
        if key not in self._heat_capacities:
            if len(self._heat_capacities) > 64:
                self._heat_capacities.clear()
            self._heat_capacities[key] = heat_capacity(pv, temperature_k)
        capacity = self._heat_capacities[key]
        l_n, l_p = (model.built_values[k] for k in THICKNESS_KEYS)
        return capacity.j_m3_k(l_n, l_p) / capacity.j_m3_k(l_n * np.asarray(factors.get("thickness_n", 1.0)),
                                                           l_p * np.asarray(factors.get("thickness_p", 1.0)))

    def _batch_factors(self, params: PackParams, model: LinearSpm, base: ParameterSets, values: dict,
                       temperature_k: float) -> dict:
        scalable = self._scalable_keys(params)
        unknown = set(values) - set(scalable) - _STATE_KEYS
        if unknown:
            raise SimulationError(f"engine batch: cannot vary {', '.join(sorted(unknown))} without a rebuild")
        factors = dict(vars(base))
        for key, arr in values.items():
            if key in scalable:
                factors[scalable[key]] = np.asarray(arr, dtype=float) / model.built_values[key]
        if model.thermal is not None:
            factors["heat_rate"] = self._heat_rate(model, self._parameter_values(params),
                                                   temperature_k, factors)
        return factors

    def _initial_concentrations(self, params: PackParams, request: SimulationRequest, model: LinearSpm) -> tuple[float, float]:
        """(c_n, c_p) in mol/m3 for the request's SOC or pack open-circuit voltage, else the params' own."""
        pv = self._parameter_values(params)
        if request.initial_soc is None and request.initial_pack_ocv_v is None:
            return float(pv[C_N0]), float(pv[C_P0])
        window = StoichiometryWindow(model, pv)
        if request.initial_soc is not None:
            return window.concentrations(soc=float(request.initial_soc))
        assert request.initial_pack_ocv_v is not None  # neither given was answered above
        return window.concentrations(ocv_v=float(request.initial_pack_ocv_v) / params.series)

    def _parameter_values(self, params: PackParams) -> pybamm.ParameterValues:
        """The params' PyBaMM parameter values (cached on the cell values; do not modify the result)."""
        key = (params.base_parameter_set, repr(sorted(params.cell_values.items())))
        if key not in self._values:
            if len(self._values) >= self.cache_size:
                self._values.pop(next(iter(self._values)))
            self._values[key] = prepared_parameter_values(params)
        return self._values[key]

    def _simulate(self, params: PackParams, request: SimulationRequest, model: LinearSpm, modal: ModalSystem,
                  sets: ParameterSets, tic: float) -> PackSimResult:
        temperature_k = float(request.ambient_temperature_k or params.ambient_temperature_k)
        c_n0, c_p0 = self._initial_concentrations(params, request, model)
        load = request.load
        duration_s = np.diff(load.edges_s())
        cell_current_a = load.current_a / params.parallel
        t_engine = time.perf_counter()
        t_out = request.output_times()
        if "hysteresis" in params.extensions:
            return self._simulate_hysteresis(params, request, model, modal, sets, (c_n0, c_p0), tic)
        step = np.clip(np.searchsorted(load.start_s, t_out, side="right") - 1, 0, load.start_s.size - 1)
        on_starts = bool(np.all(t_out == load.start_s[step]))  # then the run's step-start voltages are the report
        weak = weak_group_fraction(params)
        if weak != 1.0:  # the weak series group: the same cell with its electrode height scaled
            sets = replace(sets, height=np.asarray(sets.height, dtype=float) * np.array([1.0, weak]))
        runs = run_cells(model, modal, duration_s, cell_current_a, c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                         temperature_k=temperature_k, sets=sets, backend=self.backend, keep_states=not on_starts,
                         diffusivity_temperature=self._diffusivity_table(params, model, temperature_k))
        first = int(np.argmin(runs.end_time_s))  # the pack ends with the group that ends first
        end_time_s = float(runs.end_time_s[first])
        reached = bool(runs.reached_cutoff[first])
        keep = t_out < end_time_s if reached else t_out <= end_time_s
        t_out = t_out[keep]
        cell_temperature_k = None
        if on_starts:
            v_cells = runs.start_voltage_v[:, step[keep]]
            if model.thermal is not None:
                cell_temperature_k = runs.extra["temperature_k"][0, step[keep]]
        else:
            v_cells = voltages_at_times(model, runs, modal, duration_s, cell_current_a, t_out)
            if model.thermal is not None:
                cell_temperature_k = temperatures_at_times(runs, modal, t_out)[0]
        engine_s = time.perf_counter() - t_engine
        i_pack = load.current_at(t_out)
        r_eq = _series_resistance_ohm(params, temperature_k if cell_temperature_k is None else cell_temperature_k)
        v_pack = pack_voltage_v(v_cells[0], i_pack, series=params.series, r_eq_ohm=r_eq,
                                weak_cell_voltage_v=v_cells[1] if len(v_cells) > 1 else None)
        if not np.all(np.isfinite(v_pack)):
            raise SimulationError("engine simulation produced non-finite voltages")
        return PackSimResult(
            time_s=t_out,
            pack_voltage_v=v_pack,
            pack_current_a=i_pack,
            min_cell_voltage_v=np.min(v_cells, axis=0),
            termination="cell_cutoff" if reached else "end_of_load",
            end_time_s=end_time_s,
            seconds=time.perf_counter() - tic,
            extra={"r_eq_ohm": r_eq, "engine_seconds": engine_s, "engine_backend": runs.extra["backend"],
                   "thermal": "isothermal" if model.thermal is None else "lumped",
                   "group_cell_voltage_v": np.asarray(v_cells),
                   **({} if cell_temperature_k is None else {"cell_temperature_k": cell_temperature_k})},
        )


    def _simulate_hysteresis(self, params: PackParams, request: SimulationRequest, model: LinearSpm, modal: ModalSystem,
                             sets: ParameterSets, c0: tuple[float, float], tic: float) -> PackSimResult:
        """:meth:`_simulate` with the ``hysteresis`` extension's voltage (isothermal cells)."""
        from battery_predictor.simulation.engine.hysteresis import Hysteresis, run_cell

        temperature_k = float(request.ambient_temperature_k or params.ambient_temperature_k)
        load = request.load
        duration_s = np.diff(load.edges_s())
        cell_current_a = load.current_a / params.parallel
        pv = self._parameter_values(params)
        term = Hysteresis(half_width_v=hysteresis_half_width_v(params, temperature_k),
                          rate_per_c=hysteresis_rate_per_c(params, pv),
                          initial_state=extension_value(params, HYS_INITIAL),
                          relax_per_s=extension_value(params, HYS_RELAX))
        t_engine = time.perf_counter()
        run = run_cell(model, modal, duration_s, cell_current_a, c_n0_mol_m3=c0[0], c_p0_mol_m3=c0[1],
                       temperature_k=temperature_k, sets=sets, backend=self.backend, hysteresis=term,
                       time_s=request.output_times())
        engine_s = time.perf_counter() - t_engine
        i_pack = load.current_at(run.time_s)
        r_eq = _series_resistance_ohm(params, temperature_k)
        v_pack = pack_voltage_v(run.cell_voltage_v, i_pack, series=params.series, r_eq_ohm=r_eq)
        if not np.all(np.isfinite(v_pack)):
            raise SimulationError("engine simulation produced non-finite voltages")
        return PackSimResult(
            time_s=run.time_s,
            pack_voltage_v=v_pack,
            pack_current_a=i_pack,
            min_cell_voltage_v=run.cell_voltage_v,
            termination="cell_cutoff" if run.reached_cutoff else "end_of_load",
            end_time_s=run.end_time_s,
            seconds=time.perf_counter() - tic,
            extra={"r_eq_ohm": r_eq, "engine_seconds": engine_s, "engine_backend": run.backend,
                   "thermal": "isothermal", "hysteresis_state": run.hysteresis_state,
                   "group_cell_voltage_v": np.asarray(run.cell_voltage_v)[None, :],
                   "final_hysteresis_state": run.final_state},
        )


class _Overlay:
    """Parameter values with some keys replaced (read-only)."""

    def __init__(self, base: pybamm.ParameterValues, overrides: dict[str, float]) -> None:
        self._base = base
        self._overrides = overrides

    def __getitem__(self, key: str) -> Any:
        return self._overrides[key] if key in self._overrides else self._base[key]
