"""Segment runs on the engine for predictions: from an SOC or a carried state, sampled inside segments.

:class:`EnginePack` is the engine's counterpart of the predictor's re-solvable PyBaMM pack model: a
pack of identical cells (the cell carries ``I_pack / parallel``; :func:`pack_voltage_v` with
``R_eq``) runs ``[(duration_s, pack_current_a), ...]`` from a state of charge (uniform particles,
PyBaMM's linear SOC between the 0 % and 100 % open-circuit voltages) or from the particle state a
previous run ended in, and reports the pack voltage at samples inside every segment (each
segment's end sampled under the segment's own current) until the cell's lower cut-off.

A weak series group (extension ``cell_imbalance``) is a second cell whose electrode height is the
weak fraction of the normal one's (a parameter set of the same extraction, no rebuild). The groups
were full together: from an SOC (the weak group's) the normal cells start higher
(:func:`~battery_predictor.simulation.extensions.group_socs`); the pack voltage is ``(series - 1) V_normal + V_weak - I R_eq`` and the run ends
when either cell reaches the cut-off.

Params with the PyBaMM option ``{"thermal": "lumped"}`` run lumped thermal cells
(:mod:`~battery_predictor.simulation.engine.thermal`): ``temperature_k`` of a run is the ambient
temperature, the cells start at it from an SOC or at the temperature a carried state ended at
(:attr:`EngineState.cell_temperature_k`), and the series resistance's Arrhenius factor follows the
normal cells' temperature at every sample.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.base import SegmentRun
from battery_predictor.simulation.cell_setup import prepared_parameter_values
from battery_predictor.simulation.engine.modal import modal_system, step_coefficients
from battery_predictor.simulation.engine.model import diffusivity_m2_s, extract_linear_spm
from battery_predictor.simulation.engine.pack import pack_voltage_v, series_resistance_factor
from battery_predictor.simulation.engine.run import (
    CellRuns,
    ParameterSets,
    batch_arrays,
    run_cells,
    set_surfaces_at_times,
    set_voltage_v,
    temperatures_at_times,
    thermal_state_at,
)
from battery_predictor.simulation.engine.simulator import CELL_MODEL_EXTENSIONS, DIFFUSIVITY_KEYS
from battery_predictor.simulation.engine.state import StoichiometryWindow
from battery_predictor.simulation.engine.thermal import DiffusivityTemperature, diffusivity_temperature
from battery_predictor.simulation.extensions import group_socs, pack_soc_bounds
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

if TYPE_CHECKING:
    from battery_predictor.params import PackParams

#: Stoichiometries a starting SOC must keep away from 0 and 1.
_SOC_MARGIN = 0.02
#: Temperatures (K) at which a new pack checks that its diffusivities are constant in the stoichiometry.
_PROBE_TEMPERATURES_K = (263.15, 313.15)


@dataclass(frozen=True)
class EngineState:
    """Where a run ended, to continue from.

    Attributes
    ----------
    particles : tuple of numpy.ndarray
        Negative and positive particle states (stoichiometry profiles).
    weak_particles : tuple of numpy.ndarray or None
        The weak group's particle states (extension ``cell_imbalance``), else None.
    soc_start : float
        SOC the first run started from.
    charge_ah : float
        Net pack charge drawn since then (Ah, positive = discharge).
    cell_temperature_k : numpy.ndarray or None
        Lumped thermal cells: the temperature (K) of the normal cells and, with a weak group, of
        the weak group's; None for isothermal cells.
    """

    particles: tuple[np.ndarray, np.ndarray]
    soc_start: float
    charge_ah: float
    weak_particles: tuple[np.ndarray, np.ndarray] | None = None
    cell_temperature_k: np.ndarray | None = None



@dataclass(frozen=True)
class EngineRunEnd:
    """How a run of segments ends, without the samples inside them (:meth:`EnginePack.run_end`).

    Attributes
    ----------
    pack_voltage_v : float
        Pack voltage in V at the end of the last segment under its current (the last sample of
        :meth:`EnginePack.run`); NaN when the cut-off was reached.
    reached_cutoff : bool
        True when a cell reached its lower cut-off before the end.
    end_time_s : float
        When the run ended (s from the start).
    """

    pack_voltage_v: float
    reached_cutoff: bool
    end_time_s: float


class EnginePack:
    """A pack of identical cells on the engine, for runs of segments (see module docstring).

    Parameters
    ----------
    params : PackParams
        The pack; extensions outside the engine's cell-model ones raise.
    current_offset_a : float
        Pack current-sensor offset (A): the cells carry ``current - offset``.
    weak_fraction : float or None
        Capacity fraction of the weak series group (1: none); required when the params activate
        ``cell_imbalance`` (its value lives with the extension, above this layer).
    series_activation_j_mol : float or None
        Arrhenius activation energy of ``R_eq`` (J/mol); required when the params activate
        ``temperature`` (the particle diffusivities' own temperature dependence comes from PyBaMM).
    resistance_factor : callable, optional
        ``resistance_factor(cell_temperature_k) -> factor`` on ``R_eq`` (float or array in, same
        shape out), e.g. the ``temperature`` extension's Arrhenius factor with its cold cell
        resistance (``simulation.extensions.series_resistance_factor``); default: the Arrhenius
        factor of ``series_activation_j_mol``.
    samples_per_segment : int
        Minimum samples inside each segment (its end always included).
    max_spacing_s : float
        Largest spacing of samples in s.
    backend : str
        Engine backend (``"auto"``, ``"numba"``, ``"numpy"``).
    """

    def __init__(self, params: PackParams, *, current_offset_a: float = 0.0, weak_fraction: float | None = None,
                 series_activation_j_mol: float | None = None, samples_per_segment: int = 4,
                 max_spacing_s: float = 30.0, backend: str = "auto",
                 resistance_factor: Callable[[npt.ArrayLike], npt.ArrayLike] | None = None) -> None:
        outside = sorted(set(params.extensions) - set(CELL_MODEL_EXTENSIONS) - {"cell_imbalance", "temperature"})
        if params.model != "SPM" or outside:
            raise SimulationError(f"the engine does not cover model {params.model} with extensions {outside}")
        if "cell_imbalance" in params.extensions and weak_fraction is None:
            raise SimulationError("cell_imbalance is active: pass the weak group's capacity fraction (weak_fraction)")
        if "temperature" in params.extensions and series_activation_j_mol is None:
            raise SimulationError("temperature is active: pass the series resistance's activation energy "
                                  "(series_activation_j_mol)")
        self.series_activation_j_mol = float(series_activation_j_mol or 0.0)
        self._resistance_factor = resistance_factor
        self.weak_fraction = 1.0 if weak_fraction is None or params.series < 2 else float(weak_fraction)
        if not 0.0 < self.weak_fraction <= 10.0:
            raise SimulationError(f"weak group capacity fraction must be > 0, got {weak_fraction}")
        self._heights = np.array([1.0, self.weak_fraction]) if self.weak_fraction != 1.0 else np.array([1.0])
        self.params = params
        self.current_offset_a = float(current_offset_a)
        self.samples_per_segment = int(samples_per_segment)
        self.max_spacing_s = float(max_spacing_s)
        self.backend = backend
        self.model = extract_linear_spm(params)
        self.modal = modal_system(self.model)
        pv = prepared_parameter_values(params)
        self._pv = pv
        self._diffusivity_factors: dict[float, tuple[float, float]] = {}
        self._sets: dict[float, tuple[ParameterSets, Any]] = {}
        self._tables: dict[float, DiffusivityTemperature] = {}
        self.window = StoichiometryWindow(self.model, pv)
        if self.model.thermal is None:  # refuse diffusivities that depend on the stoichiometry away from the build
            for temperature_k in _PROBE_TEMPERATURES_K:
                self._diffusivity_factors_at(temperature_k)
        p = params.interconnect
        self.r_eq_ohm = equivalent_network_resistance_ohm(params.series, params.parallel, p["r_b_ohm"], p["r_c_ohm"],
                                                          p["r_t_ohm"])
        volume_m3 = float(pv["Electrode height [m]"]) * float(pv["Electrode width [m]"])
        #: Pack capacity between 0 % and 100 % SOC in Ah (negative electrode window; the group that empties first).
        self.capacity_ah = (abs(self.window.x_100 - self.window.x_0) * self.window.n_n * volume_m3 * 96485.33212
                            / 3600.0 * params.parallel * min(1.0, self.weak_fraction))

    # ------------------------------------------------------------------ state
    @property
    def soc_bounds(self) -> tuple[float, float]:
        """Widest SOC range whose stoichiometries, in every group (:meth:`group_concentrations`), stay inside
        (0, 1) with a 2 % margin."""
        return pack_soc_bounds(self._cell_soc_bounds, self.weak_fraction)

    @property
    def _cell_soc_bounds(self) -> tuple[float, float]:
        """Widest SOC range of a cell whose stoichiometries stay inside (0, 1) with a 2 % margin."""
        w = self.window
        socs = []
        for x in (_SOC_MARGIN, 1.0 - _SOC_MARGIN):
            socs.append((x - w.x_0) / (w.x_100 - w.x_0))
        y_0, y_100 = float(w.y_of(w.x_0)), float(w.y_of(w.x_100))
        for y in (_SOC_MARGIN, 1.0 - _SOC_MARGIN):
            socs.append((y_0 - y) / (y_0 - y_100))
        lows, highs = sorted(socs[:2]), sorted(socs[2:])
        return max(lows[0], highs[0]), min(lows[1], highs[1])

    def concentrations(self, soc: float) -> tuple[float, float]:
        """Uniform (c_n, c_p) in mol/m3 of a cell at ``soc`` (PyBaMM's linear SOC; may lie outside 0..1)."""
        lo, hi = self._cell_soc_bounds
        if not (np.isfinite(soc) and lo - 1e-9 <= soc <= hi + 1e-9):
            raise SimulationError(f"SOC must be within {lo:.3f}..{hi:.3f} for this model, got {soc}")
        w = self.window
        x = w.x_0 + soc * (w.x_100 - w.x_0)
        return x * w.c_max_mol_m3[0], float(w.y_of(x)) * w.c_max_mol_m3[1]

    def group_concentrations(self, soc: float) -> list[tuple[float, float]]:
        """Uniform (c_n, c_p) in mol/m3 of each group at the pack's ``soc``: the normal cells', then the weak
        group's (:func:`~battery_predictor.simulation.extensions.group_socs`: the groups were full together)."""
        if self._heights.size == 1:
            return [self.concentrations(soc)]
        return [self.concentrations(group_soc) for group_soc in group_socs(soc, self.weak_fraction)]

    def soc_of(self, state: EngineState) -> float:
        """SOC of a carried state: start SOC minus the charge drawn over the capacity."""
        return state.soc_start - state.charge_ah / self.capacity_ah

    @property
    def thermal(self) -> bool:
        """True when the cells are lumped thermal cells (a run's ``temperature_k`` is then the ambient)."""
        return self.model.thermal is not None

    def at_cell_temperature(self, start: float | EngineState, cell_temperature_k: float) -> float | EngineState:
        """``start`` with its cells at ``cell_temperature_k`` (K) instead of the ambient or a carried temperature.

        Lumped thermal cells only (isothermal cells return ``start`` unchanged, their temperature is the
        run's). An SOC becomes the state a run from that SOC starts in (uniform particles, each group at
        its SOC, :meth:`group_concentrations`), so a run from it equals the run from the SOC but for the starting temperature.

        Raises
        ------
        SimulationError
            When ``cell_temperature_k`` is not a finite temperature within 200..400 K.
        """
        if self.model.thermal is None:
            return start
        if not (math.isfinite(cell_temperature_k) and 200.0 < cell_temperature_k < 400.0):
            raise SimulationError(f"cell temperature {cell_temperature_k} K is outside 200..400 K")
        temperatures = np.full(self._heights.size, float(cell_temperature_k))
        if isinstance(start, EngineState):
            return replace(start, cell_temperature_k=temperatures)
        normal, *weak = (self.model.initial_state(*c) for c in self.group_concentrations(float(start)))
        return EngineState(particles=normal, soc_start=float(start), charge_ah=0.0,
                           weak_particles=weak[0] if weak else None, cell_temperature_k=temperatures)

    # ------------------------------------------------------------------- runs
    def run(self, start: float | EngineState, segments: npt.ArrayLike, temperature_k: float) -> SegmentRun:
        """Run ``segments`` = [(duration_s, pack_current_a), ...] at ``temperature_k`` from an SOC or a state.

        A cell below its cut-off as soon as the first segment's current flows gives a run of one NaN
        sample at 0 s with ``reached_cutoff`` set.
        """
        duration_s, pack_a, cell_a, common = self._inputs(segments, temperature_k)
        common["keep_states"] = True
        if self.model.thermal is not None:
            common["diffusivity_temperature"] = self._table_at(float(temperature_k))
            if isinstance(start, EngineState) and start.cell_temperature_k is not None:
                common["initial_temperature_k"] = np.broadcast_to(start.cell_temperature_k, self._heights.shape)
        runs = self._run_cells(start, duration_s, cell_a, common)
        if isinstance(start, EngineState):
            soc_start, charge0 = start.soc_start, start.charge_ah
        else:
            soc_start, charge0 = float(start), 0.0
        return self._samples(runs, duration_s, pack_a, cell_a, soc_start, charge0)

    def _inputs(self, segments: npt.ArrayLike,
                temperature_k: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Checked segment durations (s), pack and cell currents (A) and the kernel's common arguments."""
        segs = np.asarray(segments, dtype=float).reshape(-1, 2)
        # contiguous columns: the compiled kernel has one specialisation for every caller (and the warm-up)
        duration_s, pack_a = np.ascontiguousarray(segs[:, 0]), np.ascontiguousarray(segs[:, 1])
        if segs.size == 0 or not (np.all(duration_s > 0) and np.all(np.isfinite(segs))):
            raise SimulationError("segments must be finite (duration > 0 s, current) pairs")
        if not np.isfinite(temperature_k) or not 200.0 < temperature_k < 400.0:
            raise SimulationError(f"temperature {temperature_k} K is outside 200..400 K")
        cell_a = (pack_a - self.current_offset_a) / self.params.parallel
        sets, batch = self._sets_at(float(temperature_k))
        return duration_s, pack_a, cell_a, dict(temperature_k=float(temperature_k), backend=self.backend, sets=sets,
                                                batch=batch)

    def _sets_at(self, temperature_k: float) -> tuple[ParameterSets, Any]:
        """The groups' parameter sets at ``temperature_k`` and the kernel's per-set arrays of them (cached per
        temperature: a route answer runs the same few temperatures every time)."""
        cached = self._sets.get(temperature_k)
        if cached is None:
            if len(self._sets) > 64:
                self._sets.clear()
            f_n, f_p = self._diffusivity_factors_at(temperature_k)
            sets = ParameterSets(height=self._heights, diffusivity_n=f_n, diffusivity_p=f_p)
            batch = batch_arrays(self.model, self.modal, sets, self._heights.size, temperature_k)
            for value in vars(batch).values():  # shared by every run at this temperature: never written
                if isinstance(value, np.ndarray):
                    value.flags.writeable = False
            cached = self._sets[temperature_k] = (sets, batch)
        return cached

    def _run_cells(self, start: float | EngineState, duration_s: np.ndarray, cell_a: np.ndarray,
                   common: dict[str, Any]) -> CellRuns:
        """The kernel's run of every group from an SOC or a carried state (with its weak group)."""
        if isinstance(start, EngineState):
            particles = start.particles
            if self._heights.size > 1:
                if start.weak_particles is None:
                    raise SimulationError("the state to continue from has no weak group (made without cell_imbalance?)")
                weak = start.weak_particles
                particles = (np.vstack([particles[0], weak[0]]), np.vstack([particles[1], weak[1]]))
            return run_cells(self.model, self.modal, duration_s, cell_a, initial_state=particles, **common)
        c_n, c_p = (np.array(c) for c in zip(*self.group_concentrations(float(start)), strict=True))
        return run_cells(self.model, self.modal, duration_s, cell_a, c_n0_mol_m3=c_n, c_p0_mol_m3=c_p, **common)

    def run_end(self, start: float | EngineState, segments: npt.ArrayLike, temperature_k: float) -> EngineRunEnd:
        """Only the end of :meth:`run`: its last pack voltage, whether and when it reached the cut-off.

        The same recurrence and voltage expression as :meth:`run`, without the samples inside the
        segments and the final state (for a route decision: the fused compiled kernel, one call for
        every group; about 0.1 ms for the longest route instead of about 1 ms). Lumped thermal cells
        take :meth:`run`.
        """
        if self.model.thermal is not None:
            run = self.run(start, segments, temperature_k)
            return EngineRunEnd(math.nan if run.reached_cutoff else float(run.pack_voltage_v[-1]),
                                bool(run.reached_cutoff), float(run.end_time_s))
        duration_s, pack_a, cell_a, common = self._inputs(segments, temperature_k)
        runs = self._run_cells(start, duration_s, cell_a, common)
        first = int(np.argmin(runs.end_time_s))  # the group that reaches its cut-off first ends the pack's run
        end_s = float(runs.end_time_s[first])
        if runs.reached_cutoff[first]:
            return EngineRunEnd(math.nan, True, end_s)
        cell_v = runs.end_voltage_v[:, -1]
        r_eq = self.r_eq_ohm * self.resistance_factor(float(temperature_k))
        v_pack = pack_voltage_v(cell_v[0], pack_a[-1] - self.current_offset_a, series=self.params.series,
                                r_eq_ohm=r_eq, weak_cell_voltage_v=cell_v[1] if cell_v.size > 1 else None)
        return EngineRunEnd(float(v_pack), False, end_s)

    def warm_up(self, temperature_k: float) -> None:
        """Compile what :meth:`run_end` and :meth:`run` use (a route end, a sampled run to the cut-off), so that
        the first answers do not (Numba compiles on first use, seconds, holding the GIL)."""
        low, high = self.soc_bounds
        self.run_end(0.5 * (low + high), [(60.0, 1.0), (60.0, 0.5)], temperature_k)
        self.run(0.5 * (low + high), [(60.0, 0.5), (7200.0, 2.0 * self.capacity_ah)], temperature_k)

    def _samples(self, runs: CellRuns, duration_s: np.ndarray, pack_a: np.ndarray, cell_a: np.ndarray,
                 soc_start: float, charge0: float) -> SegmentRun:
        first = int(np.argmin(runs.end_time_s))  # the group that reaches its cut-off first ends the pack's run
        end_s = float(runs.end_time_s[first])
        reached = bool(runs.reached_cutoff[first])
        last = int(runs.cutoff_step[first]) if reached else duration_s.size - 1
        # every completed segment: t0 + np.linspace(0, h, n + 1), for all at once (the same floating-point values)
        full = last if reached else last + 1
        h = np.asarray(duration_s[:full], dtype=float)
        n = np.maximum(self.samples_per_segment, np.ceil(h / self.max_spacing_s).astype(np.int64))
        sizes = n + 1
        owner = np.repeat(np.arange(full), sizes)
        first_index = np.cumsum(sizes) - sizes
        offset = (np.arange(int(sizes.sum())) - np.repeat(first_index, sizes)).astype(float) * np.repeat(h / n, sizes)
        end_index = first_index + n
        offset[end_index] = h
        time_s = np.repeat(np.asarray(runs.step_start_s[:full], dtype=float), sizes) + offset
        ends = end_index.tolist()
        if reached:  # the segment of the cut-off: its samples before the cut-off, then the cut-off
            t0, h_last = float(runs.step_start_s[last]), float(duration_s[last])
            if end_s > t0:  # else below the cut-off as soon as this segment's current flows
                n_last = max(self.samples_per_segment, int(np.ceil(h_last / self.max_spacing_s)))
                t = t0 + np.linspace(0.0, h_last, n_last + 1)
                t = np.append(t[t < end_s], end_s)
                time_s = np.concatenate([time_s, t])
                owner = np.concatenate([owner, np.full(t.size, last)])
        state = self._state_at(runs, duration_s, cell_a, first, end_s, soc_start, charge0)
        if time_s.size == 0:  # at the cut-off as soon as the first segment's current flows
            return SegmentRun(np.zeros(1), np.full(1, np.nan), np.zeros(1), [], True, 0.0, state)
        v_cells, cell_temperatures = [], []
        for s in range(runs.end_time_s.size):
            surfaces, cell_temperature_k = self._surfaces(runs, s, duration_s, cell_a, time_s, owner)
            cell_temperatures.append(cell_temperature_k)
            v_cells.append(set_voltage_v(self.model, runs, s, surfaces, cell_a[owner], cell_temperature_k))
        pack_i = np.asarray(pack_a, dtype=float)[owner]
        r_eq = self.r_eq_ohm * self.resistance_factor(cell_temperatures[0])
        v_pack = pack_voltage_v(v_cells[0], pack_i - self.current_offset_a, series=self.params.series,
                                r_eq_ohm=r_eq, weak_cell_voltage_v=v_cells[1] if len(v_cells) > 1 else None)
        done = last if reached else duration_s.size
        charge_as = float(np.sum(duration_s[:done] * pack_a[:done]))
        if reached:
            charge_as += (end_s - float(runs.step_start_s[done])) * pack_a[done]
        state = EngineState(particles=state.particles, soc_start=soc_start, charge_ah=charge0 + charge_as / 3600.0,
                            weak_particles=state.weak_particles, cell_temperature_k=state.cell_temperature_k)
        return SegmentRun(time_s=time_s, pack_voltage_v=v_pack, pack_current_a=pack_i, segment_end_index=ends,
                                reached_cutoff=reached, end_time_s=end_s, final_state=state)

    def resistance_factor(self, temperature_k: npt.ArrayLike) -> np.ndarray:
        """Factor on ``R_eq`` at the cell temperature (K; float or array)."""
        if self._resistance_factor is not None:
            return np.asarray(self._resistance_factor(temperature_k), dtype=float)
        return series_resistance_factor(temperature_k, self.series_activation_j_mol)

    def _diffusivity_factors_at(self, temperature_k: float) -> tuple[float, float]:
        """Particle diffusivities at ``temperature_k`` over the extraction's (1 for constants)."""
        if temperature_k not in self._diffusivity_factors:
            if len(self._diffusivity_factors) > 64:
                self._diffusivity_factors.clear()
            f_n, f_p = (diffusivity_m2_s(self._pv, key, temperature_k) / self.model.built_values[key]
                        for key in DIFFUSIVITY_KEYS)
            self._diffusivity_factors[temperature_k] = (f_n, f_p)
        return self._diffusivity_factors[temperature_k]

    def _table_at(self, temperature_k: float) -> DiffusivityTemperature:
        """Thermal cells: the diffusivities' temperature dependence relative to ``temperature_k``."""
        if temperature_k not in self._tables:
            if len(self._tables) > 64:
                self._tables.clear()
            self._tables[temperature_k] = diffusivity_temperature(self._pv, DIFFUSIVITY_KEYS, temperature_k)
        return self._tables[temperature_k]

    def _surfaces(self, runs: CellRuns, set_index: int, duration_s: np.ndarray, cell_a: np.ndarray, time_s: np.ndarray,
                  owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Surface stoichiometries (n, 2) and cell temperatures (K) of one set at ``time_s``, each inside (or at
        the end of) its own segment."""
        surfaces = np.empty((time_s.size, 2))
        temperature_k = np.empty(time_s.size)
        tau = time_s - runs.step_start_s[owner]
        at_end = tau >= duration_s[owner] - 1e-12
        surfaces[at_end] = runs.extra["surfaces"][set_index, owner[at_end] + 1]
        if self.model.thermal is None:
            temperature_k[:] = runs.extra["batch"].temperature_k[set_index]
        else:
            temperature_k[at_end] = runs.extra["temperature_k"][set_index, owner[at_end] + 1]
        inside = ~at_end
        if inside.any():
            surfaces[inside] = set_surfaces_at_times(runs, self.modal, duration_s, cell_a, time_s[inside], set_index)
            if self.model.thermal is not None:
                temperature_k[inside] = temperatures_at_times(runs, self.modal, time_s[inside])[set_index]
        return surfaces, temperature_k

    def _state_at(self, runs: CellRuns, duration_s: np.ndarray, cell_a: np.ndarray, first: int, end_s: float,
                  soc_start: float,
                  charge0: float) -> EngineState:
        """Particle states of every group at ``end_s`` (the first group's end: its own final state)."""
        particles, temperatures = [], []
        for s in range(runs.end_time_s.size):
            if s == first:
                particles.append((runs.final_state[0][s], runs.final_state[1][s]))
                if self.model.thermal is not None:
                    temperatures.append(float(runs.extra["final_temperature_k"][s]))
                continue
            if self.model.thermal is not None:
                z, temperature_k = thermal_state_at(runs, self.modal, s, end_s)
                y_n, y_p = self.modal.block_states(z)
                particles.append((y_n[0], y_p[0]))
                temperatures.append(temperature_k)
                continue
            step = min(int(np.searchsorted(runs.step_start_s, end_s, side="right")) - 1, duration_s.size - 1)
            tau = end_s - float(runs.step_start_s[step])
            lam, drive = runs.extra["lam"][s], runs.extra["drive"][s]
            decay, phi = step_coefficients(lam, tau)
            z = decay * runs.extra["checkpoints"][s, step] + phi * drive * cell_a[step]
            y_n, y_p = self.modal.block_states(z)
            particles.append((y_n[0], y_p[0]))
        return EngineState(particles=particles[0], soc_start=soc_start, charge_ah=charge0,
                           weak_particles=particles[1] if len(particles) > 1 else None,
                           cell_temperature_k=np.array(temperatures) if temperatures else None)
