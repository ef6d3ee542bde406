"""Reference pack simulator: every cell simulated by liionpack (as in the seed paper).

liionpack steps all cells at a fixed period, re-solving the pack netlist
(busbars R_b, cell connections R_c, cell Thevenin resistances R_i) at each step.
The simulation terminates when any cell reaches the cell-level lower cut-off.
Note: liionpack 0.4.0 uses R_i only as the first step's guess and replaces it by
``(OCV - V) / I`` of each cell model at every step.
With the extension ``temperature`` the interconnect resistances (R_b, R_c, R_t) carry the
Arrhenius factor of the pack's series resistance at the request's temperature
(:func:`interconnect_resistance_factor`), as the fast simulator's ``R_eq`` does.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.params import PackParams
from battery_predictor.simulation.base import PackSimResult, SimulationRequest
from battery_predictor.simulation.cell_setup import (
    build_model,
    initial_concentrations,
    prepared_parameter_values,
    quiet_pybamm,
)
from battery_predictor.simulation.extensions import imbalance_cell_inputs, series_resistance_factor
from battery_predictor.simulation.load import StepLoad

if TYPE_CHECKING:
    import pybamm

#: liionpack 0.4.0 passes per-cell inputs by position: the current first, then the others in the
#: order given, while PyBaMM orders inputs alphabetically. Inputs are therefore passed sorted, and a
#: parameter whose name sorts before the current's is passed under a renamed input.
CURRENT_INPUT = "Current function [A]"
RENAMED_INPUT_PREFIX = "Per-cell "


def liionpack_input_name(key: str) -> str:
    """Name under which a per-cell PyBaMM parameter is passed to liionpack (see above)."""
    return key if key > CURRENT_INPUT else RENAMED_INPUT_PREFIX + key


def interconnect_resistance_factor(params: PackParams, temperature_k: float) -> float:
    """Factor (-) on the netlist's interconnect resistances ``R_b``, ``R_c``, ``R_t`` at ``temperature_k`` (K).

    The extension ``temperature`` makes the pack's series resistance follow an Arrhenius law
    (:func:`~battery_predictor.simulation.extensions.series_resistance_factor`); the fast
    simulator and the predictor's runner scale the reduced ``R_eq`` by it, so here every
    resistance ``R_eq`` is reduced from is scaled (``R_eq`` is, to second order, proportional to
    them). It is taken at the request's temperature, which is the cells' temperature in the
    isothermal model; with self-heating (``Total heat transfer coefficient`` fitted, lumped
    thermal model) the netlist keeps the ambient value while the fast simulator follows the
    cells' temperature. 1 without the extension.
    """
    return float(series_resistance_factor(params, float(temperature_k)))


class LiionpackSimulator:
    """liionpack pack simulation (see module docstring).

    Parameters
    ----------
    period_s : float or None
        Step period in s (default 10 s; the load is resampled conserving charge); None uses the
        load's shortest step (at least 1 s).
    output_variables : tuple of str
        Extra per-cell PyBaMM variables to record (e.g. ``"Volume-averaged cell temperature [K]"``);
        returned in ``result.extra["variables"][name]`` as arrays of shape (steps, cells).
    """

    name = "liionpack"

    def __init__(self, period_s: float | None = 10.0, output_variables: tuple[str, ...] = ()) -> None:
        self.period_s = period_s
        self.output_variables = tuple(output_variables)

    def simulate(self, params: PackParams, request: SimulationRequest) -> PackSimResult:
        """Simulate ``request`` on the pack ``params``; see :class:`PackSimulator`."""
        tic = time.perf_counter()
        load = request.load
        period_s = self.period_s or max(1.0, float(np.min(np.diff(load.edges_s()))))
        stepped = load.resample(period_s)
        temperature_k = float(request.ambient_temperature_k or params.ambient_temperature_k)
        out = solve_liionpack(
            params, stepped, period_s, temperature_k=temperature_k, initial_soc=request.initial_soc,
            initial_cell_ocv_v=None if request.initial_pack_ocv_v is None else request.initial_pack_ocv_v / params.series,
            cell_inputs=request.cell_inputs or imbalance_cell_inputs(params),  # extension cell_imbalance
            resistance_factor=interconnect_resistance_factor(params, temperature_k),  # extension temperature
            initial_cell_voltage_v=float(params.cell_lower_cutoff_v + 0.5), output_variables=self.output_variables)
        return self._result(params, request, stepped, out, tic, self.output_variables)

    @staticmethod
    def _result(params: PackParams, request: SimulationRequest, stepped: StepLoad, out: dict[str, Any], tic: float,
                output_variables: Sequence[str] = ()) -> PackSimResult:
        t_steps = np.asarray(out["Time [s]"], dtype=float)
        if t_steps.size == 0:
            raise SimulationError("liionpack simulation produced no steps")
        v_pack = np.asarray(out["Pack terminal voltage [V]"], dtype=float)
        cell_v = np.asarray(out["Terminal voltage [V]"], dtype=float)
        n_planned = len(stepped.start_s)
        cutoff = params.cell_lower_cutoff_v
        reached = len(t_steps) < n_planned or bool(np.any(cell_v[-1] < cutoff))
        termination = "cell_cutoff" if reached else "end_of_load"
        end_time = float(t_steps[-1] + (0.0 if reached else stepped.end_s - t_steps[-1]))
        t_out = request.output_times()
        t_out = t_out[t_out <= t_steps[-1] + 1e-9]
        idx = np.clip(np.searchsorted(t_steps, t_out + 1e-9, side="right") - 1, 0, len(t_steps) - 1)
        return PackSimResult(
            time_s=t_out,
            pack_voltage_v=v_pack[idx],
            pack_current_a=request.load.current_at(t_out),
            min_cell_voltage_v=cell_v.min(axis=1)[idx],
            termination=termination,
            end_time_s=end_time,
            seconds=time.perf_counter() - tic,
            extra={"cell_voltage_v": cell_v, "cell_current_a": np.asarray(out["Cell current [A]"]),
                   "step_time_s": t_steps, "period_s": float(stepped.start_s[1] - stepped.start_s[0])
                   if len(stepped.start_s) > 1 else float(stepped.end_s),
                   "variables": {name: np.asarray(out[name]) for name in output_variables}},
        )


def solve_liionpack(params: PackParams, stepped: StepLoad, period_s: float, *, temperature_k: float,
                    initial_cell_voltage_v: float, initial_soc: float | None = None,
                    initial_cell_ocv_v: float | None = None, cell_inputs: Mapping[str, Any] | None = None,
                    resistance_factor: float = 1.0, output_variables: Sequence[str] = (),
                    node_termination: Callable[[Any], Callable[[np.ndarray], bool]] | None = None,
                    failure: str = "liionpack simulation failed") -> dict[str, Any]:
    """Set up and solve the pack ``params`` cell by cell with liionpack (the one liionpack solve).

    Parameters
    ----------
    params : PackParams
        The pack (its interconnect resistances make the netlist).
    stepped : StepLoad
        Pack current (A, discharge positive) on steps of ``period_s``.
    period_s : float
        liionpack step period in s.
    temperature_k : float
        Ambient and initial temperature in K.
    initial_cell_voltage_v : float
        The netlist's first guess of the cell voltage (V).
    initial_soc, initial_cell_ocv_v : float, optional
        Initial state of every cell (SOC 0..1 or open-circuit voltage in V); neither keeps the params'
        initial concentrations.
    cell_inputs : mapping, optional
        Per-cell PyBaMM parameter values (each ``n_cells`` long), passed as liionpack inputs
        (:func:`liionpack_input_name`).
    resistance_factor : float
        Factor on ``R_b``, ``R_c`` and ``R_t`` (:func:`interconnect_resistance_factor`).
    output_variables : sequence of str
        Extra per-cell PyBaMM variables to record.
    node_termination : callable, optional
        Given the netlist, returns liionpack's ``node_termination_func`` (called once per step with the
        node voltages; True stops the solve).
    failure : str
        Start of the :class:`SimulationError` message when liionpack fails.

    Returns
    -------
    dict
        liionpack's output (``"Time [s]"``, ``"Pack terminal voltage [V]"``, per-cell variables).
    """
    import liionpack as lp
    import pybamm

    lp.set_logging_level("ERROR")
    import liionpack.solvers  # noqa: F401  (so quiet_pybamm can silence its progress bar)

    pv = prepared_parameter_values(params)
    pv["Ambient temperature [K]"] = temperature_k
    pv["Initial temperature [K]"] = temperature_k
    c_n0, c_p0 = initial_concentrations(params, pv, initial_soc=initial_soc, initial_cell_ocv_v=initial_cell_ocv_v)
    pv["Initial concentration in negative electrode [mol.m-3]"] = c_n0
    pv["Initial concentration in positive electrode [mol.m-3]"] = c_p0
    inputs = None
    if cell_inputs:
        inputs = {}
        for key, values in cell_inputs.items():
            arr = np.asarray(values, dtype=float)
            if arr.shape != (params.n_cells,):
                raise SimulationError(f"cell input '{key}' must have {params.n_cells} values, got {arr.shape}")
            name = liionpack_input_name(key)
            pv[key] = pybamm.InputParameter(name)
            inputs[name] = arr
        inputs = dict(sorted(inputs.items()))
    p = params.interconnect
    netlist = lp.setup_circuit(Np=params.parallel, Ns=params.series, Rb=p["r_b_ohm"] * resistance_factor,
                               Rc=p["r_c_ohm"] * resistance_factor, Ri=p["r_i_ohm"],
                               Rt=p["r_t_ohm"] * resistance_factor, I=float(stepped.current_a[0]),
                               V=initial_cell_voltage_v)
    experiment = pybamm.Experiment(
        [pybamm.step.current(np.column_stack([stepped.start_s, stepped.current_a]), period=period_s)],
        period=f"{period_s} seconds",
    )

    def sim_func(parameter_values: pybamm.ParameterValues) -> pybamm.Simulation:
        return pybamm.Simulation(model=build_model(params, for_liionpack=True), parameter_values=parameter_values,
                                 solver=pybamm.CasadiSolver(mode="safe"))

    extra = {} if node_termination is None else {"node_termination_func": node_termination(netlist)}
    try:
        with quiet_pybamm():
            return lp.solve(netlist=netlist, sim_func=sim_func, parameter_values=pv, experiment=experiment,
                            inputs=inputs, initial_soc=None, nproc=1, manager="casadi",
                            output_variables=list(output_variables) or None, **extra)
    except (pybamm.SolverError, ValueError, ZeroDivisionError, RuntimeError, KeyError) as exc:
        raise SimulationError(f"{failure}: {str(exc).splitlines()[0]}") from None


def pack_terminal_nodes(netlist: Any) -> tuple[int, int]:
    """(negative, positive) node of the pack's current source in a liionpack netlist."""
    i_map = netlist["desc"].str.find("I") > -1
    node_a, node_b = (int(n) for n in netlist.loc[i_map, ["node2", "node1"]].values.flatten())
    return node_a, node_b
