"""A built pack model that re-solves for any SOC, current and temperature without rebuilding.

The cell model is built once with the applied current, the initial electrode
concentrations and the temperature as PyBaMM ``[input]`` parameters. A pack of
identical cells is then simulated as in the fast simulator: the cell carries
``I_pack / parallel`` and the pack voltage is ``series * V_cell - I_pack * R_eq``.
Piecewise-constant loads are solved segment by segment, continuing from the
previous segment's state (``Simulation.step``), so answering a route request
costs a few milliseconds.

With the extension ``cell_imbalance`` the pack holds ``series - 1`` normal groups and one
weak group, as in the fast simulator: a second model, built for one cell of the weak group
(electrode height scaled by the weak fraction,
:func:`~battery_predictor.simulation.extensions.weak_group_params`), is stepped with the
same segments and inputs; the pack voltage is ``(series - 1) * V_normal + V_weak - I_pack * R_eq``
and the run ends when either group reaches its lower cut-off. The groups were full together
(:func:`~battery_predictor.simulation.extensions.group_socs`): a run from an SOC starts the weak
group at that SOC and the normal groups higher, as the same charge drawn from full leaves them. The
pack's usable capacity and its SOC are those of the group that empties first.

With the PyBaMM option ``{"thermal": "lumped"}`` the cells self-heat from the run's (ambient)
temperature, a continued run carries their temperature in its solution, and the series
resistance's Arrhenius factor follows the cell temperature at every sample.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.base import SegmentRun
from battery_predictor.simulation.cell_setup import build_model, model_options, prepared_parameter_values, quiet_pybamm
from battery_predictor.simulation.extensions import (
    current_offset_a,
    group_socs,
    pack_soc_bounds,
    series_resistance_factor,
    weak_group_fraction,
    weak_group_params,
)
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

if TYPE_CHECKING:
    import pybamm

    from battery_predictor.params import PackParams

_CURRENT = "Current function [A]"
_C_N0 = "Initial concentration in negative electrode [mol.m-3]"
_C_P0 = "Initial concentration in positive electrode [mol.m-3]"
_T_AMB = "Ambient temperature [K]"
_T_INIT = "Initial temperature [K]"
#: The lumped thermal model's cell temperature (option ``{"thermal": "lumped"}``).
_T_CELL = "Volume-averaged cell temperature [K]"
#: Shortest step (s) taken to bring a group to the other group's cut-off time.
_MIN_STEP_S = 1e-6


@dataclass(frozen=True)
class RunState:
    """The model state at the end of a run, to continue from (keeps concentration gradients).

    Attributes
    ----------
    solution : object
        The PyBaMM solution whose last state is continued (the normal cells).
    base_inputs : dict
        The ``[input]`` values the run used (initial concentrations of its start, temperature).
    soc_start : float
        SOC the run started from.
    charge_ah : float
        Net charge drawn since then, Ah (positive = discharge).
    weak_solution : object or None
        The weak group's PyBaMM solution at the same time (extension ``cell_imbalance``), else None.
    """

    solution: object
    base_inputs: dict
    soc_start: float
    charge_ah: float
    weak_solution: object | None = None



def _build_simulation(params: PackParams) -> pybamm.Simulation:
    """A built PyBaMM simulation of one cell of ``params`` with current, concentrations and temperature as inputs."""
    import pybamm

    pv = prepared_parameter_values(params)
    for key in (_CURRENT, _C_N0, _C_P0, _T_AMB, _T_INIT):
        pv[key] = "[input]"
    try:
        with quiet_pybamm():
            sim = pybamm.Simulation(build_model(params), parameter_values=pv,
                                    solver=pybamm.IDAKLUSolver(rtol=1e-6, atol=1e-8))
            sim.build()
    except Exception as exc:  # noqa: BLE001 - any build failure is a model failure for the caller
        raise SimulationError(f"{params.source}: cannot build the pack model: {str(exc).splitlines()[0]}") from None
    return sim


def _step(sim: pybamm.Simulation, solution: pybamm.Solution | None, duration_s: float, inputs: dict,
          t_interp: np.ndarray) -> tuple[pybamm.Solution, np.ndarray, np.ndarray]:
    """Step ``sim`` by ``duration_s`` from ``solution``; returns (solution, time_s from the step's start, cell V)."""
    new = sim.step(duration_s, starting_solution=solution, inputs=inputs, save=False, t_interp=t_interp)
    time_s = np.asarray(new.t, dtype=float)
    time_s = time_s - time_s[0]
    cell_voltage_v = np.asarray(new["Terminal voltage [V]"].entries, dtype=float)
    return new, time_s, cell_voltage_v


def _stopped_early(solution: pybamm.Solution, time_s: np.ndarray, duration_s: float) -> bool:
    """True when a step ended at the cell's lower cut-off (or otherwise before ``duration_s``)."""
    return bool(solution.termination and "Minimum voltage" in str(solution.termination)
                or time_s[-1] < duration_s - 1e-6)


class PackRunner:
    """Re-solvable pack model for predictions (thread-safe; one solve at a time).

    Parameters
    ----------
    params : PackParams
        The fitted pack model.
    samples_per_segment : int
        Minimum output samples inside each segment (the end is always included).
    max_spacing_s : float
        Maximum spacing of output samples in s.
    """

    def __init__(self, params: PackParams, samples_per_segment: int = 4, max_spacing_s: float = 30.0) -> None:
        from dataclasses import replace

        self.params = params
        self.samples_per_segment = samples_per_segment
        self.max_spacing_s = max_spacing_s
        self._lock = threading.Lock()
        self._pv_numeric = prepared_parameter_values(params)
        self._sim = _build_simulation(params)
        #: extension cell_imbalance: capacity fraction of the weak series group (1 = no weak group)
        self.weak_fraction = weak_group_fraction(params)
        #: the weak group's model (one cell of the group), built only with the extension
        self._weak_sim = None
        if self.weak_fraction != 1.0:
            self._weak_sim = _build_simulation(replace(weak_group_params(params), series=1))
        p = params.interconnect
        self.r_eq_ohm = equivalent_network_resistance_ohm(params.series, params.parallel, p["r_b_ohm"], p["r_c_ohm"],
                                                          p["r_t_ohm"])
        #: extension current_offset: currents given to run() are sensor readings; the cells carry reading - offset
        self.current_offset_a = current_offset_a(params)

    # ------------------------------------------------------------------ state
    @cached_property
    def stoichiometry_window(self) -> tuple[float, float, float, float]:
        """(x_0%, x_100%, y_100%, y_0%): electrode stoichiometries at 0 % and 100 % SOC.

        The weak group of ``cell_imbalance`` only has a smaller electrode area, so it shares them.
        """
        import pybamm

        try:
            x0, x100, y100, y0 = pybamm.lithium_ion.get_min_max_stoichiometries(self._pv_numeric)
        except Exception as exc:  # noqa: BLE001
            raise SimulationError(f"cannot compute the SOC window: {str(exc).splitlines()[0]}") from None
        return float(x0), float(x100), float(y100), float(y0)

    @cached_property
    def soc_bounds(self) -> tuple[float, float]:
        """Widest SOC range whose stoichiometries, in every group, stay inside (0, 1) with a 2 % margin.

        SOC here is PyBaMM's linear coordinate between the 0 % and 100 % OCV points
        (``Open-circuit voltage at 0%/100% SOC``); a pack may be used beyond them (e.g. below
        0 % when the robot's cut-off is lower than the 0 % OCV), so states outside 0..1 are valid.
        """
        x0, x100, y100, y0 = self.stoichiometry_window
        margin = 0.02
        dx, dy = x100 - x0, y0 - y100
        lows = [(margin - x0) / dx if dx > 0 else -0.5, (y0 - (1 - margin)) / dy if dy > 0 else -0.5]
        highs = [((1 - margin) - x0) / dx if dx > 0 else 1.5, (y0 - margin) / dy if dy > 0 else 1.5]
        # with a weak group: where every group's SOC (group_socs) stays inside the cell's range
        return pack_soc_bounds((max(-0.5, max(lows)), min(1.5, min(highs))), self.weak_fraction)

    @cached_property
    def capacity_ah(self) -> float:
        """Usable pack capacity between 0 % and 100 % SOC in Ah (from the negative electrode window).

        With ``cell_imbalance`` the group that empties first (the weak group when its fraction
        is below 1) limits it: ``min(1, weak_fraction)`` x the normal groups' capacity.
        """
        pv = self._pv_numeric
        x0, x100, _, _ = self.stoichiometry_window
        f = 96485.33212
        volume = (pv["Negative electrode thickness [m]"] * pv["Electrode height [m]"] * pv["Electrode width [m]"]
                  * pv["Negative electrode active material volume fraction"])
        normal_ah = float(abs(x100 - x0) * pv["Maximum concentration in negative electrode [mol.m-3]"] * volume * f
                          / 3600.0 * self.params.parallel)
        return normal_ah * min(1.0, self.weak_fraction)

    def concentrations(self, soc: float) -> tuple[float, float]:
        """Initial electrode concentrations (mol/m3) at ``soc`` (linear in stoichiometry, as PyBaMM)."""
        x0, x100, y100, y0 = self.stoichiometry_window
        c_n = float(self._pv_numeric["Maximum concentration in negative electrode [mol.m-3]"])
        c_p = float(self._pv_numeric["Maximum concentration in positive electrode [mol.m-3]"])
        return (x0 + soc * (x100 - x0)) * c_n, (y0 - soc * (y0 - y100)) * c_p

    # ------------------------------------------------------------------- runs
    def run(self, start: float | RunState, segments: Sequence[tuple[float, float]], temperature_k: float) -> SegmentRun:
        """Run ``segments`` = [(duration_s, pack_current_a), ...] at ``temperature_k``.

        ``start`` is a SOC (uniform, relaxed particles; with ``cell_imbalance`` each group at its
        SOC, :func:`~battery_predictor.simulation.extensions.group_socs`) or a :class:`RunState` to continue from. Stops early when a cell reaches its
        lower cut-off (with ``cell_imbalance``: a cell of either group).
        """
        import pybamm

        if not np.isfinite(temperature_k) or not 200.0 < temperature_k < 400.0:
            raise SimulationError(f"temperature {temperature_k} K is outside 200..400 K")
        weak_sim = self._weak_sim
        base, sol, sol_w, soc_start, charge0 = self._start(start, temperature_k)
        base_w = self._weak_start(start, base)
        r_factor = float(series_resistance_factor(self.params, temperature_k))
        thermal = model_options(self.params).get("thermal", "isothermal") == "lumped"
        times, volts, amps, ends = [], [], [], []
        t0, cutoff, charge_as = 0.0, False, 0.0
        with self._lock, quiet_pybamm():
            for duration_s, current_a in segments:
                duration_s, current_a = float(duration_s), float(current_a)
                if not (duration_s > 0 and np.isfinite(duration_s) and np.isfinite(current_a)):
                    raise SimulationError(f"invalid segment ({duration_s} s, {current_a} A)")
                inputs = dict(base)
                inputs[_CURRENT] = (current_a - self.current_offset_a) / self.params.parallel
                n = max(self.samples_per_segment, int(np.ceil(duration_s / self.max_spacing_s)))
                t_interp = np.linspace(0.0, duration_s, n + 1)
                new_w = None
                try:
                    new, t_seg, v_cell = _step(self._sim, sol, duration_s, inputs, t_interp)
                    t_cell = np.asarray(new[_T_CELL].entries, dtype=float).ravel() if thermal else None
                    stopped = _stopped_early(new, t_seg, duration_s)
                    if weak_sim is not None:
                        inputs_w = {**base_w, _CURRENT: inputs[_CURRENT]}
                        new_w, t_w, v_w = _step(weak_sim, sol_w, duration_s, inputs_w, t_interp)
                        stopped = stopped or _stopped_early(new_w, t_w, duration_s)
                except (pybamm.SolverError, ValueError, ZeroDivisionError, RuntimeError) as exc:
                    self._sim._solution = None
                    if weak_sim is not None:
                        weak_sim._solution = None
                    if "Minimum voltage" in str(exc) and "initial conditions" in str(exc):
                        cutoff = True  # already at the cut-off under this segment's current
                        break
                    raise SimulationError(f"pack model failed: {str(exc).splitlines()[0]}") from None
                if weak_sim is None:
                    v_pack = self.params.series * v_cell
                else:  # extension cell_imbalance: the group that reached its cut-off first ends the segment
                    t_seg, v_pack, t_cell, new, new_w = self._with_weak_group(
                        (t_seg, v_cell, t_cell, sol, new), (t_w, v_w, sol_w, new_w), (inputs, inputs_w))
                times.append(t0 + t_seg)
                # a lumped thermal cell: the series resistance's Arrhenius factor at the cell temperature
                factor = r_factor if t_cell is None else series_resistance_factor(self.params, t_cell)
                volts.append(v_pack - (current_a - self.current_offset_a) * self.r_eq_ohm * factor)
                amps.append(np.full(t_seg.size, current_a))
                ends.append(sum(len(x) for x in times) - 1)
                t0 += float(t_seg[-1])
                charge_as += float(t_seg[-1]) * current_a
                sol, sol_w = new, new_w
                if stopped:
                    cutoff = True
                    ends.pop()
                    break
            self._sim._solution = None
            if weak_sim is not None:
                weak_sim._solution = None
        final = None if sol is None else RunState(sol, base, soc_start, charge0 + charge_as / 3600.0, sol_w)
        if not times:  # cut-off before the first segment could start
            return SegmentRun(np.zeros(1), np.full(1, np.nan), np.zeros(1), [], True, 0.0, None)
        return SegmentRun(time_s=np.concatenate(times), pack_voltage_v=np.concatenate(volts),
                          pack_current_a=np.concatenate(amps), segment_end_index=ends, reached_cutoff=cutoff,
                          end_time_s=t0, final_state=final)

    def _start(self, start: float | RunState, temperature_k: float
               ) -> tuple[dict[str, float], pybamm.Solution | None, pybamm.Solution | None, float, float]:
        """What a run starts from: (the ``[input]`` values, the normal and the weak group's solution to continue
        (None from an SOC), the SOC the state started from, the charge drawn since then in Ah)."""
        if isinstance(start, RunState):
            sol, sol_w = start.solution, start.weak_solution
            if self._weak_sim is not None and sol is not None and sol_w is None:
                raise SimulationError("the state to continue from has no weak-group solution "
                                      "(made by a runner without cell_imbalance?)")
            base = dict(start.base_inputs)
            base[_T_AMB] = float(temperature_k)
            return base, sol, sol_w, start.soc_start, start.charge_ah
        soc = float(start)
        lo, hi = self.soc_bounds
        if not np.isfinite(soc) or not (lo - 1e-9 <= soc <= hi + 1e-9):
            raise SimulationError(f"SOC must be within {lo:.3f}..{hi:.3f} for this model, got {soc}")
        normal_soc = group_socs(soc, weak_group_fraction(self.params))[0] if self._weak_sim is not None else soc
        c_n0, c_p0 = self.concentrations(normal_soc)
        base = {_C_N0: c_n0, _C_P0: c_p0, _T_AMB: float(temperature_k), _T_INIT: float(temperature_k)}
        return base, None, None, soc, 0.0

    def _weak_start(self, start: float | RunState, base: dict[str, float]) -> dict[str, float]:
        """The weak group's ``[input]`` values for a run whose normal cells start from ``base``.

        From an SOC the normal cells start at the normal groups' SOC and the weak group at its own
        (:func:`~battery_predictor.simulation.extensions.group_socs`); a continued run carries both groups'
        states in its solutions and the concentrations are not read.
        """
        if self._weak_sim is None or isinstance(start, RunState):
            return base
        c_n0, c_p0 = self.concentrations(group_socs(float(start), weak_group_fraction(self.params))[1])
        return {**base, _C_N0: c_n0, _C_P0: c_p0}

    def _with_weak_group(self, normal: tuple[np.ndarray, np.ndarray, np.ndarray | None, pybamm.Solution | None,
                                             pybamm.Solution],
                         weak: tuple[np.ndarray, np.ndarray, pybamm.Solution | None, pybamm.Solution],
                         inputs: tuple[dict, dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, pybamm.Solution,
                                                             pybamm.Solution]:
        """One segment of the pack with a weak group (extension ``cell_imbalance``).

        ``normal`` is a normal cell's (times s, voltage V, temperature K or None, solution before, solution
        after) and ``weak`` the weak group's (times, voltage, solution before, after). The group that reached
        its cut-off first ends the segment: the other is interpolated onto its times and re-stepped to its
        end. ``inputs`` are the normal and the weak group's ``[input]`` values. Returns (times s, pack
        voltage V without the series resistance, cell temperature K or None, normal solution, weak solution).
        """
        t_seg, v_cell, t_cell, sol, new = normal
        t_w, v_w, sol_w, new_w = weak
        assert self._weak_sim is not None  # called only with a weak group
        if t_w[-1] < t_seg[-1]:
            v_cell = np.interp(t_w, t_seg, v_cell)
            if t_cell is not None:
                t_cell = np.interp(t_w, t_seg, t_cell)
            t_seg = t_w
            new = self._truncated(self._sim, sol, new, float(t_w[-1]), inputs[0])
        else:
            v_w = np.interp(t_seg, t_w, v_w)
            if t_seg[-1] < t_w[-1]:
                new_w = self._truncated(self._weak_sim, sol_w, new_w, float(t_seg[-1]), inputs[1])
        return t_seg, (self.params.series - 1) * v_cell + v_w, t_cell, new, new_w

    @staticmethod
    def _truncated(sim: pybamm.Simulation, start_solution: pybamm.Solution | None, longer_solution: pybamm.Solution,
                   duration_s: float, inputs: dict) -> pybamm.Solution:
        """``sim``'s state ``duration_s`` after ``start_solution`` (the other group's cut-off time).

        Re-steps the group that ran past the other's cut-off, so that both solutions of the
        final state describe the same time; keeps ``longer_solution`` when that fails.
        """
        import pybamm

        if duration_s <= _MIN_STEP_S:
            return start_solution if start_solution is not None else longer_solution
        try:
            new, _, _ = _step(sim, start_solution, duration_s, inputs, np.array([0.0, duration_s]))
        except (pybamm.SolverError, ValueError, ZeroDivisionError, RuntimeError):
            return longer_solution
        return new

    def soc_of(self, state: RunState) -> float:
        """SOC of a continued state: start SOC minus the charge drawn over :attr:`capacity_ah`.

        With ``cell_imbalance`` this is the SOC of the group that limits the pack (the weak
        group when its fraction is below 1), as both groups start at the same SOC.
        """
        return state.soc_start - state.charge_ah / self.capacity_ah

    def settled_voltage_v(self, soc: float, current_a: float, temperature_k: float, settle_s: float = 60.0) -> float:
        """Pack voltage (V) after ``settle_s`` at a constant ``current_a`` from ``soc``; NaN past cut-off."""
        run = self.run(soc, [(settle_s, current_a)], temperature_k)
        return float("nan") if run.reached_cutoff else float(run.pack_voltage_v[-1])
