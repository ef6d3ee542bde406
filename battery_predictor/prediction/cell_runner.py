"""A built pack model that re-solves for any SOC, current and temperature without rebuilding.

The cell model is built once with the applied current, the initial electrode
concentrations and the temperature as PyBaMM ``[input]`` parameters. A pack of
identical cells is then simulated as in the fast simulator: the cell carries
``I_pack / parallel`` and the pack voltage is ``series * V_cell - I_pack * R_eq``.
Piecewise-constant loads are solved segment by segment, continuing from the
previous segment's state (``Simulation.step``), so answering a route request
costs a few milliseconds.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.cell_setup import build_model, prepared_parameter_values, quiet_pybamm
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

_CURRENT = "Current function [A]"
_C_N0 = "Initial concentration in negative electrode [mol.m-3]"
_C_P0 = "Initial concentration in positive electrode [mol.m-3]"
_T_AMB = "Ambient temperature [K]"
_T_INIT = "Initial temperature [K]"


@dataclass(frozen=True)
class RunState:
    """The model state at the end of a run, to continue from (keeps concentration gradients).

    Attributes
    ----------
    solution : object
        The PyBaMM solution whose last state is continued.
    base_inputs : dict
        The ``[input]`` values the run used (initial concentrations of its start, temperature).
    soc_start : float
        SOC the run started from.
    charge_ah : float
        Net charge drawn since then, Ah (positive = discharge).
    """

    solution: object
    base_inputs: dict
    soc_start: float
    charge_ah: float


@dataclass(frozen=True)
class SegmentRun:
    """Result of running a sequence of constant-current segments.

    Attributes
    ----------
    time_s : numpy.ndarray
        Sample times in s from the start.
    pack_voltage_v : numpy.ndarray
        Pack voltage in V at those times.
    pack_current_a : numpy.ndarray
        Pack current in A (positive = discharge).
    segment_end_index : list of int
        Index into ``time_s`` of the last sample of each completed segment.
    reached_cutoff : bool
        True when a cell reached its lower cut-off before the end.
    end_time_s : float
        Time in s at which the run ended.
    final_state : RunState or None
        State at the end, to continue from.
    """

    time_s: np.ndarray
    pack_voltage_v: np.ndarray
    pack_current_a: np.ndarray
    segment_end_index: list[int]
    reached_cutoff: bool
    end_time_s: float
    final_state: RunState | None = None


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

    def __init__(self, params, samples_per_segment: int = 4, max_spacing_s: float = 30.0) -> None:
        import pybamm

        self.params = params
        self.samples_per_segment = samples_per_segment
        self.max_spacing_s = max_spacing_s
        self._lock = threading.Lock()
        pv = prepared_parameter_values(params)
        self._pv_numeric = prepared_parameter_values(params)
        for key in (_CURRENT, _C_N0, _C_P0, _T_AMB, _T_INIT):
            pv[key] = "[input]"
        try:
            with quiet_pybamm():
                self._sim = pybamm.Simulation(build_model(params), parameter_values=pv,
                                              solver=pybamm.IDAKLUSolver(rtol=1e-6, atol=1e-8))
                self._sim.build()
        except Exception as exc:  # noqa: BLE001 - any build failure is a model failure for the caller
            raise SimulationError(f"{params.source}: cannot build the pack model: {str(exc).splitlines()[0]}") from None
        p = params.interconnect
        self.r_eq_ohm = equivalent_network_resistance_ohm(params.series, params.parallel, p["r_b_ohm"], p["r_c_ohm"],
                                                          p["r_t_ohm"])
        from battery_predictor.diagnosis.extensions_impl import current_offset_a

        #: extension current_offset: currents given to run() are sensor readings; the cells carry reading - offset
        self.current_offset_a = current_offset_a(params)

    # ------------------------------------------------------------------ state
    @cached_property
    def stoichiometry_window(self) -> tuple[float, float, float, float]:
        """(x_0%, x_100%, y_100%, y_0%): electrode stoichiometries at 0 % and 100 % SOC."""
        import pybamm

        try:
            x0, x100, y100, y0 = pybamm.lithium_ion.get_min_max_stoichiometries(self._pv_numeric)
        except Exception as exc:  # noqa: BLE001
            raise SimulationError(f"cannot compute the SOC window: {str(exc).splitlines()[0]}") from None
        return float(x0), float(x100), float(y100), float(y0)

    @cached_property
    def soc_bounds(self) -> tuple[float, float]:
        """Widest SOC range whose stoichiometries stay inside (0, 1) with a 2 % margin.

        SOC here is PyBaMM's linear coordinate between the 0 % and 100 % OCV points
        (``Open-circuit voltage at 0%/100% SOC``); a pack may be used beyond them (e.g. below
        0 % when the robot's cut-off is lower than the 0 % OCV), so states outside 0..1 are valid.
        """
        x0, x100, y100, y0 = self.stoichiometry_window
        margin = 0.02
        dx, dy = x100 - x0, y0 - y100
        lows = [(margin - x0) / dx if dx > 0 else -0.5, (y0 - (1 - margin)) / dy if dy > 0 else -0.5]
        highs = [((1 - margin) - x0) / dx if dx > 0 else 1.5, (y0 - margin) / dy if dy > 0 else 1.5]
        return max(-0.5, max(lows)), min(1.5, min(highs))

    @cached_property
    def capacity_ah(self) -> float:
        """Pack capacity between 0 % and 100 % SOC in Ah (from the negative electrode window)."""
        pv = self._pv_numeric
        x0, x100, _, _ = self.stoichiometry_window
        f = 96485.33212
        volume = (pv["Negative electrode thickness [m]"] * pv["Electrode height [m]"] * pv["Electrode width [m]"]
                  * pv["Negative electrode active material volume fraction"])
        return float(abs(x100 - x0) * pv["Maximum concentration in negative electrode [mol.m-3]"] * volume * f
                     / 3600.0 * self.params.parallel)

    def concentrations(self, soc: float) -> tuple[float, float]:
        """Initial electrode concentrations (mol/m3) at ``soc`` (linear in stoichiometry, as PyBaMM)."""
        x0, x100, y100, y0 = self.stoichiometry_window
        c_n = float(self._pv_numeric["Maximum concentration in negative electrode [mol.m-3]"])
        c_p = float(self._pv_numeric["Maximum concentration in positive electrode [mol.m-3]"])
        return (x0 + soc * (x100 - x0)) * c_n, (y0 - soc * (y0 - y100)) * c_p

    # ------------------------------------------------------------------- runs
    def run(self, start: float | RunState, segments, temperature_k: float) -> SegmentRun:
        """Run ``segments`` = [(duration_s, pack_current_a), ...] at ``temperature_k``.

        ``start`` is a SOC (uniform, relaxed particles) or a :class:`RunState` to continue from.
        Stops early when a cell reaches its lower cut-off.
        """
        import pybamm

        from battery_predictor.diagnosis.extensions_impl import series_resistance_factor

        if not np.isfinite(temperature_k) or not 200.0 < temperature_k < 400.0:
            raise SimulationError(f"temperature {temperature_k} K is outside 200..400 K")
        if isinstance(start, RunState):
            sol, soc_start, charge0 = start.solution, start.soc_start, start.charge_ah
            base = dict(start.base_inputs)
            base[_T_AMB] = float(temperature_k)
        else:
            soc = float(start)
            lo, hi = self.soc_bounds
            if not np.isfinite(soc) or not (lo - 1e-9 <= soc <= hi + 1e-9):
                raise SimulationError(f"SOC must be within {lo:.3f}..{hi:.3f} for this model, got {soc}")
            c_n0, c_p0 = self.concentrations(soc)
            base = {_C_N0: c_n0, _C_P0: c_p0, _T_AMB: float(temperature_k), _T_INIT: float(temperature_k)}
            sol, soc_start, charge0 = None, soc, 0.0
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
                try:
                    new = self._sim.step(duration_s, starting_solution=sol, inputs=inputs, save=False,
                                         t_interp=t_interp)
                except (pybamm.SolverError, ValueError, ZeroDivisionError, RuntimeError) as exc:
                    self._sim._solution = None
                    if "Minimum voltage" in str(exc) and "initial conditions" in str(exc):
                        cutoff = True  # already at the cut-off under this segment's current
                        break
                    raise SimulationError(f"pack model failed: {str(exc).splitlines()[0]}") from None
                seg = new
                t_seg = np.asarray(seg.t, dtype=float)
                t_seg = t_seg - t_seg[0]
                v_cell = np.asarray(seg["Terminal voltage [V]"].entries, dtype=float)
                times.append(t0 + t_seg)
                volts.append(self.params.series * v_cell - (current_a - self.current_offset_a) * self.r_eq_ohm
                             * float(series_resistance_factor(self.params, temperature_k)))
                amps.append(np.full(t_seg.size, current_a))
                ends.append(sum(len(x) for x in times) - 1)
                t0 += float(t_seg[-1])
                charge_as += float(t_seg[-1]) * current_a
                sol = new
                if new.termination and "Minimum voltage" in str(new.termination) or t_seg[-1] < duration_s - 1e-6:
                    cutoff = True
                    ends.pop()
                    break
            self._sim._solution = None
        final = None if sol is None else RunState(sol, base, soc_start, charge0 + charge_as / 3600.0)
        if not times:  # cut-off before the first segment could start
            return SegmentRun(np.zeros(1), np.full(1, np.nan), np.zeros(1), [], True, 0.0, None)
        return SegmentRun(time_s=np.concatenate(times), pack_voltage_v=np.concatenate(volts),
                          pack_current_a=np.concatenate(amps), segment_end_index=ends, reached_cutoff=cutoff,
                          end_time_s=t0, final_state=final)

    def soc_of(self, state: RunState) -> float:
        """SOC of a continued state (start SOC minus the charge drawn over the capacity)."""
        return state.soc_start - state.charge_ah / self.capacity_ah

    def settled_voltage_v(self, soc: float, current_a: float, temperature_k: float, settle_s: float = 60.0) -> float:
        """Pack voltage (V) after ``settle_s`` at a constant ``current_a`` from ``soc``; NaN past cut-off."""
        run = self.run(soc, [(settle_s, current_a)], temperature_k)
        return float("nan") if run.reached_cutoff else float(run.pack_voltage_v[-1])
