"""Fast pack simulator for packs of identical cells.

One PyBaMM cell carries ``I_pack / parallel``; the pack voltage is
``series * V_cell - I_pack * R_eq`` (:func:`~battery_predictor.simulation.engine.pack.pack_voltage_v`)
where ``R_eq`` is the interconnect resistance
of liionpack's netlist reduced for identical cells
(:func:`~battery_predictor.simulation.network.equivalent_network_resistance_ohm`).
The simulation ends when the cell reaches its lower cut-off (the cell-level
criterion liionpack applies to every cell).

The piecewise-constant current is a PyBaMM interpolant; parameters that do not
shape the mesh are ``[input]`` parameters, so a fit that only changes those
re-solves the same built model. Voltages are reported just after each report
time (right-continuous), as liionpack reports the voltage under the current that
starts at that time.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from typing import TYPE_CHECKING

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.base import PackSimResult, SimulationRequest
from battery_predictor.simulation.cell_setup import (
    ALWAYS_INPUT_KEYS,
    INPUT_SAFE_KEYS,
    build_model,
    initial_concentrations,
    prepared_parameter_values,
    quiet_pybamm,
)
from battery_predictor.simulation.engine.pack import pack_voltage_v
from battery_predictor.simulation.extensions import (
    BRUGGEMAN,
    BRUGGEMAN_KEYS,
    series_resistance_factor,
    weak_group_fraction,
    weak_group_params,
)
from battery_predictor.simulation.load import StepLoad
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

if TYPE_CHECKING:
    import pybamm

    from battery_predictor.params import PackParams

#: Width (s) of the ramp that stands for each current step in the interpolant.
_EDGE_S = 1e-3
#: In the isothermal SPM an electrode's thickness L and active material volume fraction eps enter
#: only as their product (capacity eps*L*A*c_max, reaction current I/(3 eps L A / R)), so a thickness
#: change is re-solved as the equivalent fraction eps * L / L_built without rebuilding the mesh.
THICKNESS_TO_FRACTION = {
    "Negative electrode thickness [m]": "Negative electrode active material volume fraction",
    "Positive electrode thickness [m]": "Positive electrode active material volume fraction",
}


def solver_stops_s(params: PackParams, load: StepLoad, t_end: float) -> list[float]:
    """The times IDAKLU must stop at: ``[0, t_end]``, and with the ``hysteresis`` extension every change of the current.

    PyBaMM's Axen hysteresis state moves only while current flows; at rest the solver's steps grow to tens of
    seconds and, told only ``[0, t_end]``, it steps over 10 s pulses (the state never moves). Each change of the
    current is stopped at on both sides of its ramp (``edge - _EDGE_S`` and ``edge``).
    """
    if "hysteresis" not in params.extensions:
        return [0.0, t_end]
    changed = np.nonzero(np.diff(load.current_a) != 0.0)[0] + 1
    edges = load.start_s[changed]
    stops = np.concatenate([[0.0], np.column_stack([edges - _EDGE_S, edges]).ravel(), [t_end]])
    stops = np.unique(stops[(stops >= 0.0) & (stops <= t_end)])
    return [float(t) for t in stops]


class FastPackSimulator:
    """Single-cell equivalent of a pack of identical cells (see module docstring).

    Parameters
    ----------
    cache_size : int
        Number of built PyBaMM simulations kept for re-solves.
    rtol, atol : float
        IDAKLU tolerances.
    """

    name = "fast"

    def __init__(self, cache_size: int = 8, rtol: float = 1e-6, atol: float = 1e-8,
                 map_thickness: bool = True) -> None:
        self._cache: OrderedDict[tuple, tuple[object, dict[str, float]]] = OrderedDict()
        self._cache_size = cache_size
        self.rtol = rtol
        self.atol = atol
        self.map_thickness = map_thickness
        self.builds = 0

    def _thickness_mappable(self, params: PackParams) -> bool:
        """True when thickness can be folded into the volume fraction (isothermal SPM, no extra options)."""
        return self.map_thickness and params.model == "SPM" and not params.options and not params.extensions

    # ----------------------------------------------------------------- public
    def simulate(self, params: PackParams, request: SimulationRequest) -> PackSimResult:
        """Simulate ``request`` on the pack ``params``; see :class:`PackSimulator`."""
        import pybamm

        if request.cell_inputs:
            raise SimulationError("the fast simulator only handles identical cells; use --simulator liionpack "
                                  "for per-cell values")
        tic = time.perf_counter()
        pv = prepared_parameter_values(params)
        temperature_k = float(request.ambient_temperature_k or params.ambient_temperature_k)
        cell_ocv = None if request.initial_pack_ocv_v is None else request.initial_pack_ocv_v / params.series
        c_n0, c_p0 = initial_concentrations(params, pv, initial_soc=request.initial_soc,
                                            initial_cell_ocv_v=cell_ocv)
        mapped = self._thickness_mappable(params)
        input_keys = set(ALWAYS_INPUT_KEYS) | (INPUT_SAFE_KEYS & set(params.cell_values))
        if mapped:
            input_keys |= set(THICKNESS_TO_FRACTION.values())
        if "electrolyte_transport" in params.extensions:  # a fitted Bruggeman exponent re-solves the built SPMe
            input_keys |= set(BRUGGEMAN_KEYS)
        inputs = {}
        for key in sorted(input_keys):
            if key in ("Ambient temperature [K]", "Initial temperature [K]"):
                inputs[key] = temperature_k
            elif key == "Initial concentration in negative electrode [mol.m-3]":
                inputs[key] = c_n0
            elif key == "Initial concentration in positive electrode [mol.m-3]":
                inputs[key] = c_p0
            else:
                val = pv[key]
                if not isinstance(val, (int, float)):
                    continue
                inputs[key] = float(val)
        sim, t_end, built_thickness = self._simulation(params, pv, request, tuple(sorted(inputs)), mapped)
        for thick_key, frac_key in THICKNESS_TO_FRACTION.items():
            if thick_key in built_thickness:
                inputs[frac_key] *= float(pv[thick_key]) / built_thickness[thick_key]
        try:
            with quiet_pybamm():
                sol = sim.solve(t_eval=np.asarray(solver_stops_s(params, request.load, t_end)), inputs=inputs)
        except (pybamm.SolverError, ValueError, ZeroDivisionError, RuntimeError) as exc:
            raise SimulationError(f"fast simulation failed: {str(exc).splitlines()[0]}") from None
        result = self._result(params, request, sol, tic)
        if weak_group_fraction(params) != 1.0:  # extension cell_imbalance: one weaker series group
            result = self._with_weak_group(params, request, result, tic)
        return result

    def _with_weak_group(self, params: PackParams, request: SimulationRequest, main: PackSimResult, tic: float) -> PackSimResult:
        """Pack of ``series - 1`` normal groups and one weak group (a second single-group run)."""
        from dataclasses import replace

        ocv = None if request.initial_pack_ocv_v is None else request.initial_pack_ocv_v / params.series
        weak = self.simulate(replace(weak_group_params(params), series=1), replace(request, initial_pack_ocv_v=ocv))
        n = min(main.time_s.size, weak.time_s.size)
        v_n, v_w = main.min_cell_voltage_v[:n], weak.min_cell_voltage_v[:n]
        i_pack = main.pack_current_a[:n]
        first = main if main.end_time_s <= weak.end_time_s else weak
        r_eq = main.extra["r_eq_ohm"]
        return PackSimResult(
            time_s=main.time_s[:n],
            pack_voltage_v=pack_voltage_v(v_n, i_pack, series=params.series, r_eq_ohm=r_eq if np.ndim(r_eq) == 0
                                          else r_eq[:n], weak_cell_voltage_v=v_w),
            pack_current_a=i_pack,
            min_cell_voltage_v=np.minimum(v_n, v_w),
            termination=first.termination,
            end_time_s=first.end_time_s,
            seconds=time.perf_counter() - tic,
            extra={**main.extra, "weak_group_cell_voltage_v": v_w},
        )

    # ---------------------------------------------------------------- helpers
    def _simulation(self, params: PackParams, pv: pybamm.ParameterValues, request: SimulationRequest,
                    input_keys: tuple[str, ...], mapped: bool) -> tuple[pybamm.Simulation, float, dict[str, float]]:
        import pybamm

        load = request.load
        skip = set(input_keys) | (set(THICKNESS_TO_FRACTION) if mapped else set())
        if set(BRUGGEMAN_KEYS) <= skip:
            skip.add(BRUGGEMAN)
        fixed = tuple(sorted((k, repr(v)) for k, v in params.cell_values.items() if k not in skip))
        key = (params.base_parameter_set, params.model, repr(sorted(params.options.items())), params.extensions,
               fixed, input_keys, load.digest(), params.parallel, mapped)
        t_end = float(load.end_s) - _EDGE_S
        if key in self._cache:
            self._cache.move_to_end(key)
            sim, built_thickness = self._cache[key]
            return sim, t_end, built_thickness
        built_thickness = {k: float(pv[k]) for k in THICKNESS_TO_FRACTION} if mapped else {}
        edges = load.edges_s()
        knots_t = np.column_stack([edges[:-1], edges[1:] - _EDGE_S]).ravel()
        knots_i = np.repeat(load.current_a / params.parallel, 2)
        for k in input_keys:
            pv[k] = "[input]"
        pv["Current function [A]"] = pybamm.Interpolant(knots_t, knots_i, pybamm.t, interpolator="linear")
        model = build_model(params)
        solver = pybamm.IDAKLUSolver(rtol=self.rtol, atol=self.atol)
        try:
            with quiet_pybamm():
                sim = pybamm.Simulation(model, parameter_values=pv, solver=solver)
                sim.build()
        except (pybamm.ModelError, pybamm.DiscretisationError, KeyError, ValueError) as exc:
            raise SimulationError(f"cannot build the cell model: {str(exc).splitlines()[0]}") from None
        self.builds += 1
        self._cache[key] = (sim, built_thickness)
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return sim, t_end, built_thickness

    def _result(self, params: PackParams, request: SimulationRequest, sol: pybamm.Solution,
                tic: float) -> PackSimResult:
        load = request.load
        t_sol_end = float(sol.t[-1])
        termination = "cell_cutoff" if sol.termination and "Minimum voltage" in str(sol.termination) else (
            "end_of_load")
        if termination != "cell_cutoff" and t_sol_end < load.end_s - 2 * _EDGE_S - 1e-6:
            termination = "cell_cutoff" if "event" in str(sol.termination) else "end_of_load"
        t_out = request.output_times()
        t_eval = np.minimum(t_out + 2 * _EDGE_S, load.end_s - 2 * _EDGE_S)
        keep = t_eval <= t_sol_end + 1e-9
        t_out, t_eval = t_out[keep], t_eval[keep]
        v_cell = np.asarray(sol["Terminal voltage [V]"](t_eval), dtype=float)
        i_pack = load.current_at(t_out)
        p = params.interconnect
        r_eq: float | np.ndarray = equivalent_network_resistance_ohm(params.series, params.parallel, p["r_b_ohm"],
                                                                     p["r_c_ohm"], p["r_t_ohm"])
        if "temperature" in params.extensions:  # extension temperature: Arrhenius series and cell resistance
            r_eq = r_eq * series_resistance_factor(
                params, np.asarray(sol["Volume-averaged cell temperature [K]"](t_eval), dtype=float))
        v_pack = pack_voltage_v(v_cell, i_pack, series=params.series, r_eq_ohm=r_eq)
        if not np.all(np.isfinite(v_pack)):
            raise SimulationError("fast simulation produced non-finite voltages")
        extra = {"r_eq_ohm": r_eq, "solution": sol}
        return PackSimResult(
            time_s=t_out,
            pack_voltage_v=v_pack,
            pack_current_a=i_pack,
            min_cell_voltage_v=v_cell,
            termination=termination,
            end_time_s=t_sol_end,
            seconds=time.perf_counter() - tic,
            extra=extra,
        )
