"""The engine behind the pack-simulator interface (:class:`~battery_predictor.simulation.base.PackSimulator`).

A pack of identical cells as in the fast simulator (the cell carries ``I_pack / parallel``, the
pack voltage is :func:`~battery_predictor.simulation.engine.pack.pack_voltage_v`, the cell's lower
cut-off ends the run, voltages are right-continuous at the report times), with the cell stepped
by the engine. Cells that differ from a built one only in particle radii, diffusivities,
electrode thicknesses, active material volume fractions and electrode height reuse its
extraction (scaling, no PyBaMM rebuild).

What the engine does not cover (models other than the SPM, the extensions outside
:data:`CELL_MODEL_EXTENSIONS`, model options or states that the voltage depends on beyond the
particle surfaces, concentration- or temperature-dependent diffusivities, per-cell values) is
simulated by the fallback simulator
(the fast one by default); the result says so in ``extra["engine_fallback"]`` and a warning is
logged, so a fallback is never silent.
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.base import PackSimResult, SimulationRequest
from battery_predictor.simulation.cell_setup import prepared_parameter_values
from battery_predictor.simulation.engine.modal import ModalSystem, modal_system
from battery_predictor.simulation.engine.model import C_N0, C_P0, EPS_N, EPS_P, HEIGHT, LinearSpm, extract_linear_spm
from battery_predictor.simulation.engine.pack import pack_voltage_v
from battery_predictor.simulation.engine.run import ParameterSets, run_cells, voltages_at_times
from battery_predictor.simulation.engine.state import StoichiometryWindow
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

LOG = logging.getLogger(__name__)

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
_STATE_KEYS = frozenset({C_N0, C_P0})
#: Extensions whose whole effect is inside PyBaMM's cell model (model options, parameter values) or
#: outside the simulator (the current offset is applied where a recording becomes a load); the
#: extraction checks that the model still splits into linear particles and a voltage function.
CELL_MODEL_EXTENSIONS = ("capacity_fade", "current_offset", "hysteresis", "resistance_growth")


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

    def __init__(self, backend: str = "auto", fallback="fast", cache_size: int = 8) -> None:
        if fallback == "fast":
            from battery_predictor.simulation.fast import FastPackSimulator

            fallback = FastPackSimulator()
        self.backend = backend
        self.fallback = fallback
        self.cache_size = cache_size
        self._cache: OrderedDict[tuple, tuple[LinearSpm, ModalSystem]] = OrderedDict()
        self._values: dict[tuple, object] = {}
        self.extractions = 0

    # ----------------------------------------------------------------- public
    def simulate(self, params, request: SimulationRequest) -> PackSimResult:
        """Simulate ``request`` on the pack ``params``; see :class:`PackSimulator`."""
        tic = time.perf_counter()
        reason = self.unsupported_reason(params, request)
        if reason is None:
            try:
                model, modal, sets = self._model(params)
            except SimulationError as exc:
                reason = str(exc)
        if reason is not None:
            return self._fall_back(params, request, reason)
        return self._simulate(params, request, model, modal, sets, tic)

    @staticmethod
    def unsupported_reason(params, request: SimulationRequest) -> str | None:
        """Why the engine cannot simulate ``request`` on ``params`` (None when it can)."""
        if request.cell_inputs:
            return "per-cell values need liionpack"
        if params.model != "SPM":
            return f"the engine covers the SPM, not the {params.model}"
        outside = sorted(set(params.extensions) - set(CELL_MODEL_EXTENSIONS))
        if outside:
            return f"the engine does not cover the extensions {outside}"
        return None

    # ---------------------------------------------------------------- helpers
    def _fall_back(self, params, request: SimulationRequest, reason: str) -> PackSimResult:
        if self.fallback is None:
            raise SimulationError(f"engine: {reason}")
        LOG.warning("engine: %s; simulating with the %s simulator", reason, self.fallback.name)
        result = self.fallback.simulate(params, request)
        result.extra["engine_fallback"] = f"{self.fallback.name}: {reason}"
        return result

    def _model(self, params) -> tuple[LinearSpm, ModalSystem, ParameterSets]:
        """The extraction for ``params`` (cached on everything but scalable values) and its scale factors."""
        values = params.cell_values
        fixed = tuple(sorted((k, repr(v)) for k, v in values.items() if k not in SCALABLE_KEYS and k not in _STATE_KEYS))
        key = (params.base_parameter_set, params.model, repr(sorted(params.options.items())), params.extensions, fixed)
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
        for pybamm_key, field_name in SCALABLE_KEYS.items():
            value = pv[pybamm_key]
            if not isinstance(value, (int, float)):
                raise SimulationError(f"'{pybamm_key}' is not a constant; the engine needs a constant")
            factors[field_name] = float(value) / model.built_values[pybamm_key]
        return model, modal, ParameterSets(**factors)

    def _initial_concentrations(self, params, request: SimulationRequest, model: LinearSpm) -> tuple[float, float]:
        """(c_n, c_p) in mol/m3 for the request's SOC or pack open-circuit voltage, else the params' own."""
        pv = self._parameter_values(params)
        if request.initial_soc is None and request.initial_pack_ocv_v is None:
            return float(pv[C_N0]), float(pv[C_P0])
        window = StoichiometryWindow(model, pv)
        if request.initial_soc is not None:
            return window.concentrations(soc=float(request.initial_soc))
        return window.concentrations(ocv_v=float(request.initial_pack_ocv_v) / params.series)

    def _parameter_values(self, params):
        """The params' PyBaMM parameter values (cached on the cell values; do not modify the result)."""
        key = (params.base_parameter_set, repr(sorted(params.cell_values.items())))
        if key not in self._values:
            if len(self._values) >= self.cache_size:
                self._values.pop(next(iter(self._values)))
            self._values[key] = prepared_parameter_values(params)
        return self._values[key]

    def _simulate(self, params, request: SimulationRequest, model: LinearSpm, modal: ModalSystem,
                  sets: ParameterSets, tic: float) -> PackSimResult:
        temperature_k = float(request.ambient_temperature_k or params.ambient_temperature_k)
        c_n0, c_p0 = self._initial_concentrations(params, request, model)
        load = request.load
        duration_s = np.diff(load.edges_s())
        cell_current_a = load.current_a / params.parallel
        t_engine = time.perf_counter()
        runs = run_cells(model, modal, duration_s, cell_current_a, c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                         temperature_k=temperature_k, sets=sets, backend=self.backend, keep_states=True)
        end_time_s = float(runs.end_time_s[0])
        t_out = request.output_times()
        t_out = t_out[t_out < end_time_s] if runs.reached_cutoff[0] else t_out[t_out <= end_time_s]
        v_cell = voltages_at_times(model, runs, modal, duration_s, cell_current_a, t_out)[0]
        engine_s = time.perf_counter() - t_engine
        i_pack = load.current_at(t_out)
        p = params.interconnect
        r_eq = equivalent_network_resistance_ohm(params.series, params.parallel, p["r_b_ohm"], p["r_c_ohm"],
                                                 p["r_t_ohm"])
        v_pack = pack_voltage_v(v_cell, i_pack, series=params.series, r_eq_ohm=r_eq)
        if not np.all(np.isfinite(v_pack)):
            raise SimulationError("engine simulation produced non-finite voltages")
        return PackSimResult(
            time_s=t_out,
            pack_voltage_v=v_pack,
            pack_current_a=i_pack,
            min_cell_voltage_v=v_cell,
            termination="cell_cutoff" if runs.reached_cutoff[0] else "end_of_load",
            end_time_s=end_time_s,
            seconds=time.perf_counter() - tic,
            extra={"r_eq_ohm": r_eq, "engine_seconds": engine_s, "engine_backend": runs.extra["backend"]},
        )
