"""Re-solvable pack simulations for the diagnosis (one build per model structure and recording).

The diagnosis evaluates hundreds of parameter sets on the same recordings, so it cannot
rebuild a PyBaMM model per evaluation. :class:`Engine` builds each model structure once
per recording, with every value a fit may change as a PyBaMM ``[input]`` parameter, and
re-solves it. The pack is simulated as in :class:`~battery_predictor.simulation.fast.FastPackSimulator`
(identical cells, ``V_pack = series * V_cell - I_pack * R_eq``, the cell current is
``I_pack / parallel``, the cell lower cut-off ends the run, voltages are right-continuous at
the report times), so that the diagnosis baseline is the fast simulator's model; a unit test
checks both agree. What the candidates add on top:

* ``Current sensor offset [A]`` is an input of the current function (the model is driven
  by the measured current minus the offset);
* a contact resistance (PyBaMM ``"contact resistance"`` option: ``V = V_internal - I_cell R``)
  is applied after the solve, which is exact because the contact drop does not feed back
  into the cell states; the cut-off is then checked on the corrected voltage;
* a weak series group (cell imbalance) is a second solve of the same model with a smaller
  electrode height; the pack voltage is ``(series - 1) V_cell + V_weak - I R_eq`` and the run
  ends when either cell reaches the cut-off.

Electrode thicknesses are folded into the volume fractions for the isothermal SPM (exact, see
:data:`battery_predictor.simulation.fast.THICKNESS_TO_FRACTION`).
"""

from __future__ import annotations

import math
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import InputDataError, SimulationError
from battery_predictor.params import INTERCONNECT_KEYS, PackParams, cached_parameter_values
from battery_predictor.recording import Recording, discharge_threshold_a, ends_at_cutoff
from battery_predictor.simulation import extensions as ext
from battery_predictor.simulation.base import SimulationRequest
from battery_predictor.simulation.cell_setup import (
    INPUT_SAFE_KEYS,
    build_model,
    prepared_parameter_values,
    quiet_pybamm,
)
from battery_predictor.simulation.engine import EngineSimulator
from battery_predictor.simulation.engine.pack import pack_voltage_v, series_resistance_factor
from battery_predictor.simulation.fast import THICKNESS_TO_FRACTION
from battery_predictor.simulation.load import StepLoad
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

if TYPE_CHECKING:
    import pybamm

_EDGE_S = 1e-3
C_N0 = "Initial concentration in negative electrode [mol.m-3]"
C_P0 = "Initial concentration in positive electrode [mol.m-3]"
EPS_N = "Negative electrode active material volume fraction"
EPS_P = "Positive electrode active material volume fraction"
L_N = "Negative electrode thickness [m]"
L_P = "Positive electrode thickness [m]"
HEIGHT = "Electrode height [m]"
T_AMB = "Ambient temperature [K]"
T_INIT = "Initial temperature [K]"
OFFSET = "Current sensor offset [A]"
#: Inputs of every build (state, temperature, the values the plain candidates change).
BASE_INPUTS = (C_N0, C_P0, T_AMB, T_INIT, EPS_N, EPS_P, HEIGHT, OFFSET)
#: A simulation of a recording stops at the cell's lower cut-off, or this far (V per cell) below the
#: lowest cell voltage the recording measured, whichever is lower. The measured current kept flowing
#: below the cut-off (cyclers that stop on charge or time, 1-10 s averages of a sub-second dip: the
#: Panasonic 0 degC drive cycles reach 2.498 V per 1 s mean and go on for minutes), so a model that
#: follows the measurement must not end there; only a model that runs out of charge (its voltage
#: plunging) ends early, and the scores pad it.
CUTOFF_MARGIN_V = 0.2


def is_mesh_free(key: str) -> bool:
    """True when ``key`` can be an ``[input]`` of a built model (or is folded/post-processed)."""
    return key in INPUT_SAFE_KEYS or key in THICKNESS_TO_FRACTION or key in INTERCONNECT_KEYS


# --------------------------------------------------------------------------- recordings
@dataclass(frozen=True)
class Observed:
    """A recording prepared for simulation and scoring.

    Attributes
    ----------
    rec : Recording
        The recording.
    t, v, i : numpy.ndarray
        Time from the first sample (s), voltage (V), current (A, positive = discharge).
    temperature_k : numpy.ndarray or None
        Measured temperature (K) or None.
    load : StepLoad
        The recorded current (zero-order hold), extended past the end at the last current when
        the recording ends at its cut-off (so that a model that would run longer shows it, as
        in R2_mod's Eq. 2).
    t_split : float
        Fit part = ``t <= t_split``; held-out part = ``t > t_split``.
    ends_at_cutoff : bool
        The recording ends at its minimum voltage under discharge (runtime is defined).
    mean_temperature_k, first_temperature_k : float
        Mean and first measured temperature (params ambient when not measured).
    """

    rec: Recording
    t: np.ndarray
    v: np.ndarray
    i: np.ndarray
    temperature_k: np.ndarray | None
    load: StepLoad
    t_split: float
    ends_at_cutoff: bool
    mean_temperature_k: float
    first_temperature_k: float
    name: str = ""

    @property
    def fit_mask(self) -> np.ndarray:
        return self.t <= self.t_split

    @property
    def held_mask(self) -> np.ndarray:
        return self.t > self.t_split

    @property
    def t_tail(self) -> np.ndarray:
        """Report times past the recording (for the late-ending case), on the median sample spacing."""
        dt = float(np.median(np.diff(self.t)))
        return np.arange(self.t[-1] + dt, self.load.end_s - 2 * _EDGE_S, dt)

    def cumulative_charge_ah(self, sensor_offset_a: float = 0.0) -> np.ndarray:
        """Charge drawn since the start at each sample (Ah, signed, discharge positive).

        ``sensor_offset_a`` (A): a current sensor offset taken off the reading, as the extension
        ``current_offset`` drives the cells with the measured current minus the offset.
        """
        return (self.load.cumulative_charge_as(self.t) - sensor_offset_a * self.t) / 3600.0


def model_cutoff_v(cutoff_cell_v: float, obs: Observed, series: int) -> float:
    """Cell voltage (V) at which a simulation of ``obs`` stops (see :data:`CUTOFF_MARGIN_V`)."""
    return min(float(cutoff_cell_v), float(np.min(obs.v)) / max(int(series), 1) - CUTOFF_MARGIN_V)


def window_average(rec: Recording, period_s: float) -> Recording:
    """Time-window averages of ``rec`` (the seed paper's processing: 10 Hz data averaged to 5 s).

    Each row is the mean of the samples in one window of ``period_s``: time, voltage, current and
    temperature; empty windows are dropped. Dense recordings (drive cycles at 1 s) cost a solver
    restart per current change; averaging them keeps the charge and the slow dynamics.
    """
    if period_s <= 0:
        raise InputDataError(f"resample period must be > 0 s, got {period_s}")
    t = rec.relative_time_s
    idx = np.floor(t / period_s).astype(int)
    _, start, counts = np.unique(idx, return_index=True, return_counts=True)

    def mean(x: npt.ArrayLike) -> np.ndarray:
        return np.add.reduceat(np.asarray(x, dtype=float), start) / counts

    temp = None if rec.temperature_k is None else mean(rec.temperature_k)
    return Recording(time_s=rec.time_s[0] + mean(t), voltage_v=mean(rec.voltage_v), current_a=mean(rec.current_a),
                     temperature_k=temp, source=rec.source, metadata=dict(rec.metadata))


def discharge_throughput_ah(t_s: np.ndarray, current_a: np.ndarray) -> np.ndarray:
    """Charge discharged since the start at each sample (Ah, discharge only, zero-order hold).

    Only discharging samples count (:func:`~battery_predictor.recording.discharge_threshold_a`): rests,
    temperature soaks and recharges do not move it.
    """
    t = np.asarray(t_s, dtype=float)
    i = np.asarray(current_a, dtype=float)
    threshold = discharge_threshold_a(i)
    if threshold <= 0.0:
        return np.zeros(t.size)
    i_dis = np.where(i > threshold, i, 0.0)
    return np.concatenate([[0.0], np.cumsum(i_dis[:-1] * np.diff(t))]) / 3600.0


def discharge_split_time_s(t_s: np.ndarray, current_a: np.ndarray, fit_fraction: float) -> float:
    """Time (s, relative) at which ``fit_fraction`` of the recording's discharge throughput is drawn.

    The fit part then holds ``fit_fraction`` of the charge the recording discharges wherever its
    discharge lies in time: a 2 h soak before a drive cycle, a charging stop in a working day or the
    rest after the cut-off do not shift the split into a part without discharge, as a split on the
    clock does. A recording without discharge is split on the clock.
    """
    t = np.asarray(t_s, dtype=float)
    q = discharge_throughput_ah(t, current_a)
    if q[-1] <= 0.0:
        return fit_fraction * float(t[-1])
    k = int(np.searchsorted(q, fit_fraction * q[-1], side="left"))
    return float(t[min(max(k, 1), t.size - 2)])


def without_trailing_rest(rec: Recording) -> Recording:
    """``rec`` up to its last discharge sample when only rest follows it (a recharge is kept).

    A test that ends with a rest after its last discharge (the Panasonic drive cycles: 300 s) adds
    samples that say nothing about the discharge, and a model that reaches its end of discharge a
    minute before the cell (1 % of the charge) would be scored as if it were empty for that whole
    rest (padded with the held-out minimum voltage against a relaxed 3.4 V): the held-out error then
    jumps by a factor 3-4 with a 1 % change of the fitted charge. Rests are dropped where the
    discharge throughput is counted too (:func:`discharge_throughput_ah`).
    """
    i = np.asarray(rec.current_a, dtype=float)
    threshold = discharge_threshold_a(i)
    if threshold <= 0.0:
        return rec
    discharging = np.nonzero(i > threshold)[0]
    last = int(discharging[-1]) if discharging.size else i.size - 1
    after = i[last + 1:]
    if after.size == 0 or np.any(after < -threshold) or last < 9:
        return rec
    return rec.slice_time(float(rec.time_s[0]), float(rec.time_s[last]))


def observe(rec: Recording, params: PackParams, fit_fraction: float = 0.6, tail_fraction: float = 0.2,
            name: str = "", split_on: str = "discharge") -> Observed:
    """Prepare ``rec`` for the diagnosis: load (with tail), split, temperatures.

    A rest after the recording's last discharge is dropped (:func:`without_trailing_rest`).

    Parameters
    ----------
    split_on : {"discharge", "time"}
        ``"discharge"`` (default): the fit part ends when ``fit_fraction`` of the recording's
        discharge throughput (Ah) is drawn (:func:`discharge_split_time_s`); ``"time"``: at
        ``fit_fraction`` of its duration.
    """
    if len(rec.time_s) < 10:
        raise InputDataError(f"{rec.source}: too few samples ({len(rec.time_s)}) to diagnose")
    rec = without_trailing_rest(rec)
    if not 0.1 <= fit_fraction <= 0.95:
        raise InputDataError(f"fit fraction must be within 0.1..0.95, got {fit_fraction}")
    t = rec.relative_time_s
    load = StepLoad.from_samples(rec.time_s, rec.current_a)
    end_cut = ends_at_cutoff(rec)
    if end_cut and tail_fraction > 0:
        # the load that ended the recording continues (a recording often ends on a current spike)
        tail_current = float(rec.current_a[-1])
        load = load.append(StepLoad.constant(tail_current, tail_fraction * float(t[-1])))
    temp = None
    if rec.temperature_k is not None and np.isfinite(rec.temperature_k).all():
        temp = np.asarray(rec.temperature_k, dtype=float)
    if split_on not in ("discharge", "time"):
        raise InputDataError(f"split_on must be 'discharge' or 'time', got {split_on!r}")
    if split_on == "discharge":
        t_split = discharge_split_time_s(t, rec.current_a, fit_fraction)
    else:
        t_split = fit_fraction * float(t[-1])
    mean_t = rec.mean_temperature_k(params.ambient_temperature_k)
    first_t = float(temp[0]) if temp is not None else params.ambient_temperature_k
    return Observed(rec=rec, t=t, v=np.asarray(rec.voltage_v, float), i=np.asarray(rec.current_a, float),
                    temperature_k=temp, load=load, t_split=t_split, ends_at_cutoff=end_cut,
                    mean_temperature_k=mean_t, first_temperature_k=first_t, name=name or str(rec.source))


# --------------------------------------------------------------------------- results
@dataclass
class SimOut:
    """A simulated recording.

    Attributes
    ----------
    t : numpy.ndarray
        Report times (s) up to the end of the run (measurement times, then the tail grid).
    v_pack : numpy.ndarray
        Pack voltage (V) at ``t``.
    v_cell_min : numpy.ndarray
        Lowest cell voltage (V).
    reached_cutoff : bool
        A cell reached its cut-off before the end of the load.
    end_time_s : float
        When the run ended.
    temperature_k : numpy.ndarray or None
        Cell temperature (K) when the model computes one.
    """

    t: np.ndarray
    v_pack: np.ndarray
    v_cell_min: np.ndarray
    reached_cutoff: bool
    end_time_s: float
    temperature_k: np.ndarray | None = None
    extra: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Post:
    """What is applied after the cell solve.

    Attributes
    ----------
    contact_resistance_ohm : float
        Contact resistance per cell (Ohm).
    weak_fraction : float
        Capacity fraction of the weak series group (1 = none).
    series_activation_j_mol : float
        Arrhenius activation energy of the pack's series resistance ``R_eq`` (fitted at the
        reference temperature): at cell temperature T it is ``R_eq exp(E/R (1/T - 1/T_ref))``.
    """

    contact_resistance_ohm: float = 0.0
    weak_fraction: float = 1.0
    series_activation_j_mol: float = 0.0


#: Run values the SPM engine path takes as parameter values (the capacity-fade candidate's volume fractions).
_ENGINE_VALUE_KEYS = frozenset({EPS_N, EPS_P})
#: The hysteresis candidate's PyBaMM inputs, as the extension's values in ``cell.extra``.
_HYSTERESIS_INPUTS = {ext.HYS_HALF_WIDTH: ext.HYS_HALF_WIDTH, ext.PYBAMM_HYS_INITIAL_KEY: ext.HYS_INITIAL,
                      **{k: ext.HYS_DECAY for k in ext.PYBAMM_HYS_DECAY_KEYS}}


def engine_params(params: PackParams, values: dict, concentrations: tuple[float, float], post: Post,
                  cutoff_v: float) -> PackParams:
    """The params a run of :meth:`Engine.simulate` means, for the SPM engine.

    The run's values (volume fractions; the hysteresis inputs as the extension's values), its initial
    concentrations (mol/m3), its cell cut-off ``cutoff_v`` (V, :func:`model_cutoff_v`) and a weak series group
    (``post.weak_fraction``, as the extension ``cell_imbalance``). The contact resistance stays a
    post-solve term (:func:`finish_run`).
    """
    updates = {k: float(v) for k, v in values.items() if k in _ENGINE_VALUE_KEYS}
    updates[C_N0], updates[C_P0] = (float(c) for c in concentrations)
    updates["Lower voltage cut-off [V]"] = float(cutoff_v)
    extra = dict(params.extra)
    extensions = list(params.extensions)
    for key, extra_key in _HYSTERESIS_INPUTS.items():
        if key in values:
            extra[extra_key] = float(values[key])
    if post.weak_fraction != 1.0:
        extensions.append("cell_imbalance")
        extra[ext.WEAK_FRACTION] = float(post.weak_fraction)
    out = replace(params, extensions=tuple(dict.fromkeys(extensions)), extra=extra)
    return out.with_values(updates)


def report_times(obs: Observed, t_end: float | None) -> np.ndarray:
    """The times (s) a simulation of ``obs`` reports: the measurement times, then the tail grid, up to ``t_end``."""
    t_all = np.concatenate([obs.t, obs.t_tail])
    return t_all if t_end is None else t_all[t_all <= t_end + 1e-9]


def finish_run(params: PackParams, obs: Observed, t_out: np.ndarray, v_cells: list[np.ndarray],
               temperature_k: np.ndarray | None, *, reached: bool, end_time_s: float, r_eq: float, post: Post,
               offset_a: float, cutoff_v: float) -> SimOut:
    """A solved recording as a :class:`SimOut`: :class:`Post`'s terms applied to the cell voltages, the pack voltage.

    Parameters
    ----------
    t_out : numpy.ndarray
        Report times (s) the solver reached.
    v_cells : list of numpy.ndarray
        Cell terminal voltage (V) at ``t_out``: the normal cells', then the weak group's (if any).
    temperature_k : numpy.ndarray or None
        Cell temperature (K) at ``t_out``; needed when ``post`` has Arrhenius terms.
    reached : bool
        The solver stopped at the cut-off.
    end_time_s : float
        When the solver stopped (s).
    r_eq : float
        The pack's series resistance at the reference temperature (Ohm).
    cutoff_v : float
        The run's cell cut-off (V, :func:`model_cutoff_v`): a corrected voltage below it ends the run.
    """
    i_pack = obs.load.current_at(t_out) - offset_a
    i_cell = i_pack / params.parallel
    v_cells = [v - i_cell * post.contact_resistance_ohm for v in v_cells]
    r_eq_t: float | np.ndarray = r_eq
    if post.series_activation_j_mol:
        assert temperature_k is not None  # the caller reads it whenever there is an activation energy
        r_eq_t = r_eq * series_resistance_factor(temperature_k, post.series_activation_j_mol)
    v_pack = pack_voltage_v(v_cells[0], i_pack, series=params.series, r_eq_ohm=r_eq_t,
                            weak_cell_voltage_v=v_cells[1] if len(v_cells) > 1 else None)
    # the cut-off sees each cell's share of the series resistance's temperature excess
    excess_per_cell_v = i_pack * (r_eq_t - r_eq) / params.series
    v_min = np.minimum.reduce([v - excess_per_cell_v for v in v_cells])
    below = np.nonzero(v_min < cutoff_v)[0]
    if below.size:  # the corrected voltage (contact drop / weak cell) reaches the cut-off first
        n = max(int(below[0]), 1)
        t_out, v_pack, v_min = t_out[:n], v_pack[:n], v_min[:n]
        reached = True
        end_time_s = float(t_out[-1])
    if temperature_k is not None:
        temperature_k = temperature_k[: t_out.size]
    if not np.all(np.isfinite(v_pack)):
        raise SimulationError("simulation produced non-finite voltages")
    return SimOut(t=t_out, v_pack=v_pack, v_cell_min=v_min, reached_cutoff=bool(reached),
                  end_time_s=float(end_time_s), temperature_k=temperature_k)


# --------------------------------------------------------------------------- engine
class Engine:
    """Builds each (structure, recording) once and re-solves it with ``[input]`` values.

    Parameters
    ----------
    rtol, atol : float
        IDAKLU tolerances (as the fast simulator).
    cache_size : int
        Built simulations kept.
    spm_engine : bool
        Run what the SPM engine covers on it (:meth:`_simulate_on_engine`); False solves everything with
        PyBaMM.
    """

    def __init__(self, rtol: float = 1e-5, atol: float = 1e-7, cache_size: int = 48, spm_engine: bool = True) -> None:
        self.rtol = rtol
        self.atol = atol
        self.cache_size = cache_size
        self._cache: OrderedDict = OrderedDict()
        self._windows: dict = {}
        self._spm: EngineSimulator | None = EngineSimulator(fallback=None, cache_size=32) if spm_engine else None
        self.builds = 0
        self.solves = 0
        #: Runs on the SPM engine, and PyBaMM solves by the reason the engine did not take them.
        self.engine_runs = 0
        self.pybamm_reasons: Counter[str] = Counter()

    # ------------------------------------------------------------------ state
    def stoichiometry_window(self, params: PackParams) -> tuple[float, float, float, float]:
        """(x_0%, x_100%, y_100%, y_0%) of ``params``, as PyBaMM's ``get_min_max_stoichiometries``.

        The electrode stoichiometries at which the open-circuit voltage equals the params'
        ``Open-circuit voltage at 0% / 100% SOC [V]`` with the lithium inventory of the initial
        concentrations, solved on tabulated OCPs (PyBaMM's own solver takes ~0.15 s a call, too slow
        inside a fit; a unit test checks both agree).
        """
        key = params.fingerprint()
        if key not in self._windows:
            pv = cached_parameter_values(params)
            tables = self._ocp_tables(params, pv)
            n_n, n_p, li = self.loadings(pv, {})
            x100 = _solve_ocv(tables, n_n, n_p, li, float(pv["Open-circuit voltage at 100% SOC [V]"]))
            x0 = _solve_ocv(tables, n_n, n_p, li, float(pv["Open-circuit voltage at 0% SOC [V]"]))
            self._windows[key] = (x0, x100, (li - n_n * x100) / n_p, (li - n_n * x0) / n_p)
        return self._windows[key]

    def _ocp_tables(self, params: PackParams,
                    pv: pybamm.ParameterValues) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        key = ("ocp", params.base_parameter_set, repr(pv["Negative electrode OCP [V]"]),
               repr(pv["Positive electrode OCP [V]"]))
        if key not in self._windows:
            grid = np.linspace(1e-6, 1.0 - 1e-6, 20001)
            self._windows[key] = (grid, _evaluate_ocp(pv["Negative electrode OCP [V]"], grid, pv),
                                  _evaluate_ocp(pv["Positive electrode OCP [V]"], grid, pv))
        return self._windows[key]

    @staticmethod
    def loadings(pv: pybamm.ParameterValues, values: dict) -> tuple[float, float, float]:
        """Per-area electrode capacities and lithium inventory (mol/m2): (n_neg, n_pos, n_li)."""
        def get(k: str) -> float:
            return float(values.get(k, pv[k]))

        n_n = get(EPS_N) * get(L_N) * float(pv["Maximum concentration in negative electrode [mol.m-3]"])
        n_p = get(EPS_P) * get(L_P) * float(pv["Maximum concentration in positive electrode [mol.m-3]"])
        li = get(EPS_N) * get(L_N) * get(C_N0) + get(EPS_P) * get(L_P) * get(C_P0)
        return n_n, n_p, li

    def concentrations_for_soc(self, params: PackParams, soc: float, *, eps_scale: tuple[float, float] = (1.0, 1.0),
                               lithium_scale: float = 1.0) -> tuple[float, float]:
        """Initial (c_n, c_p) in mol/m3 for ``soc`` in the params' window.

        ``x = x0 + soc (x100 - x0)`` in the negative electrode (PyBaMM's linear SOC), and the
        positive stoichiometry from the lithium inventory, which a capacity-fade candidate
        scales (``lithium_scale``) together with the active material (``eps_scale``). With both
        at 1 this is PyBaMM's ``get_initial_stoichiometries``.
        """
        pv = cached_parameter_values(params)
        x0, x100, _, _ = self.stoichiometry_window(params)
        n_n, n_p, li = self.loadings(pv, {})
        n_n *= eps_scale[0]
        n_p *= eps_scale[1]
        x = x0 + soc * (x100 - x0)
        y = (li * lithium_scale - n_n * x) / n_p
        c_n_max = float(pv["Maximum concentration in negative electrode [mol.m-3]"])
        c_p_max = float(pv["Maximum concentration in positive electrode [mol.m-3]"])
        if not (0.0 < x < 1.0 and 0.0 < y < 1.0):
            raise SimulationError(f"initial state outside the electrodes' range (x={x:.3f}, y={y:.3f})")
        return x * c_n_max, y * c_p_max

    # ------------------------------------------------------------------ builds
    def _build(self, params: PackParams, obs: Observed, input_keys: tuple[str, ...], temperature_trace: bool = False
               ) -> tuple[pybamm.Simulation, dict[str, float], pybamm.ParameterValues]:
        import pybamm

        mapped = _thickness_mappable(params)
        key = (params.base_parameter_set, params.model, repr(sorted(params.options.items())), params.extensions,
               repr(sorted((k, v) for k, v in params.cell_values.items()
                           if k not in input_keys and not (mapped and k in THICKNESS_TO_FRACTION))),
               input_keys, obs.load.digest(), params.parallel, mapped, temperature_trace, float(np.min(obs.v)))
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        pv = prepared_parameter_values(params)
        built_thickness = {k: float(pv[k]) for k in THICKNESS_TO_FRACTION} if mapped else {}
        for k in input_keys:
            pv.update({k: "[input]"}, check_already_exists=False)
        edges = obs.load.edges_s()
        knots_t = np.column_stack([edges[:-1], edges[1:] - _EDGE_S]).ravel()
        knots_i = np.repeat(obs.load.current_a / params.parallel, 2)
        interp = pybamm.Interpolant(knots_t, knots_i, pybamm.t, interpolator="linear")
        pv["Current function [A]"] = interp - pybamm.Parameter(OFFSET) / params.parallel
        pv["Lower voltage cut-off [V]"] = model_cutoff_v(float(pv["Lower voltage cut-off [V]"]), obs, params.series)
        if temperature_trace:  # isothermal cell at the measured temperature, a function of time
            assert obs.temperature_k is not None  # checked by the caller (simulate)
            t_meas = np.append(obs.t, obs.load.end_s + 1.0)
            temp = np.append(obs.temperature_k, obs.temperature_k[-1])
            trace = pybamm.Interpolant(t_meas, temp, pybamm.t, interpolator="linear")
            pv.update({T_AMB: lambda y, z, t: trace, T_INIT: float(obs.temperature_k[0])})
        try:
            with quiet_pybamm():
                sim = pybamm.Simulation(build_model(params), parameter_values=pv,
                                        solver=pybamm.IDAKLUSolver(rtol=self.rtol, atol=self.atol))
                sim.build()
        except Exception as exc:  # noqa: BLE001 - any build failure is a model failure here
            raise SimulationError(f"cannot build the cell model: {str(exc).splitlines()[0]}") from None
        self.builds += 1
        pv_num = prepared_parameter_values(params)
        entry = (sim, built_thickness, pv_num)
        self._cache[key] = entry
        if len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return entry

    # ------------------------------------------------------------------ runs
    def simulate(self, params: PackParams, obs: Observed, *, values: dict | None = None,
                 concentrations: tuple[float, float], ambient_k: float, t_end: float | None = None,
                 extra_inputs: tuple[str, ...] = (), post: Post = Post(), offset_a: float = 0.0,
                 want_temperature: bool = False, temperature_trace: bool = False) -> SimOut:
        """Simulate ``obs`` with ``params`` updated by ``values`` (input keys, thickness, r_b/r_c).

        Parameters
        ----------
        values : dict
            Overrides: any key of :data:`BASE_INPUTS`, ``extra_inputs``, thicknesses (folded
            into the volume fractions) and interconnect resistances.
        concentrations : (float, float)
            Initial (c_n, c_p) in mol/m3.
        ambient_k : float
            Ambient (and initial) temperature in K.
        t_end : float, optional
            Stop at this time (s); default the end of the load (recording + tail).
        extra_inputs : tuple of str
            PyBaMM keys (beyond :data:`BASE_INPUTS`) that are inputs of this structure.
        post : Post
            Contact resistance and weak group applied after the solve.
        offset_a : float
            Current sensor offset (A, pack level).
        temperature_trace : bool
            The (isothermal) cell follows the recording's measured temperature instead of ``ambient_k``.
        """
        import pybamm

        values = dict(values or {})
        offset_a = float(values.pop(OFFSET, offset_a))
        on_engine = self._simulate_on_engine(params, obs, values, concentrations=concentrations, ambient_k=ambient_k,
                                             t_end=t_end, extra_inputs=extra_inputs, post=post, offset_a=offset_a,
                                             want_temperature=want_temperature, temperature_trace=temperature_trace)
        if on_engine is not None:
            return on_engine
        value_inputs = {k for k in values if k in INPUT_SAFE_KEYS}
        unused = set(values) - value_inputs - set(extra_inputs) - set(THICKNESS_TO_FRACTION) - set(INTERCONNECT_KEYS)
        if unused:
            raise SimulationError(f"cannot vary {', '.join(sorted(unused))} without rebuilding the model")
        key_set = set(BASE_INPUTS) | set(extra_inputs) | value_inputs
        if temperature_trace:
            if obs.temperature_k is None:
                raise SimulationError(f"{obs.name}: no measured temperature to follow")
            key_set -= {T_AMB, T_INIT}
        input_keys = tuple(sorted(key_set))
        sim, built_thickness, pv = self._build(params, obs, input_keys, temperature_trace)
        inputs = {}
        for k in input_keys:
            if k in values:
                inputs[k] = float(values[k])
            elif k == OFFSET:
                inputs[k] = float(offset_a)
            elif k in (T_AMB, T_INIT):
                inputs[k] = float(ambient_k)
            elif k in (C_N0, C_P0):
                continue
            else:
                val = pv[k]
                if not isinstance(val, (int, float)):
                    raise SimulationError(f"'{k}' is not a scalar in {params.base_parameter_set}; it cannot be fitted")
                inputs[k] = float(val)
        inputs[C_N0], inputs[C_P0] = concentrations
        for thick_key, frac_key in THICKNESS_TO_FRACTION.items():
            if thick_key in built_thickness:
                inputs[frac_key] *= float(values.get(thick_key, built_thickness[thick_key])) / built_thickness[thick_key]
        t_stop = float(obs.load.end_s) - _EDGE_S if t_end is None else min(float(t_end) + 3 * _EDGE_S,
                                                                          float(obs.load.end_s) - _EDGE_S)
        runs = [inputs]
        if post.weak_fraction != 1.0:
            weak = dict(inputs)
            weak[HEIGHT] = inputs[HEIGHT] * post.weak_fraction
            runs.append(weak)
        sols = []
        for inp in runs:
            try:
                with quiet_pybamm():
                    sols.append(sim.solve(t_eval=[0.0, t_stop], inputs=inp))
            except (pybamm.SolverError, ValueError, ZeroDivisionError, RuntimeError) as exc:
                raise SimulationError(f"simulation failed: {str(exc).splitlines()[0]}") from None
            self.solves += 1
        r_eq = self._r_eq(params, values)
        return self._result(params, obs, sols, t_end, r_eq, post, offset_a, pv, want_temperature)

    def usage(self) -> tuple[int, Counter[str]]:
        """The runs so far: (on the SPM engine, PyBaMM solves by reason); see :meth:`usage_since`."""
        return self.engine_runs, Counter(self.pybamm_reasons)

    def usage_since(self, before: tuple[int, Counter[str]]) -> dict[str, Any]:
        """Which solver ran the simulations since :meth:`usage` returned ``before`` (for the JSON)."""
        reasons = Counter(self.pybamm_reasons)
        reasons.subtract(before[1])
        reasons = +reasons
        return {"engine_runs": self.engine_runs - before[0], "pybamm_runs": sum(reasons.values()),
                "pybamm_reasons": dict(reasons)}

    def engine_reason(self, values: dict, extra_inputs: tuple[str, ...], post: Post,
                      temperature_trace: bool) -> str | None:
        """Why a run with these arguments needs PyBaMM's solver (None when the SPM engine may take it)."""
        if self._spm is None:
            return "the SPM engine is switched off"
        if temperature_trace:
            return "the cell follows the measured temperature, the engine one temperature per run"
        if post.series_activation_j_mol:
            return "Arrhenius resistance terms"
        other = sorted((set(extra_inputs) | set(values)) - _ENGINE_VALUE_KEYS - set(_HYSTERESIS_INPUTS))
        if other:
            return f"the engine does not take {', '.join(other)} as run inputs"
        return None

    def _simulate_on_engine(self, params: PackParams, obs: Observed, values: dict, *,
                            concentrations: tuple[float, float], ambient_k: float, t_end: float | None,
                            extra_inputs: tuple[str, ...], post: Post, offset_a: float, want_temperature: bool,
                            temperature_trace: bool) -> SimOut | None:
        """:meth:`simulate` on the SPM engine (exact stepping of PyBaMM's discretised SPM), or None.

        The engine runs the same cell (PyBaMM's model and parameter values with the run's values,
        initial concentrations and the run's cut-off) on the recorded current as steps; the
        :class:`Post` terms are applied as after a PyBaMM solve (:func:`finish_run`). None, with the
        reason counted in :attr:`pybamm_reasons`, when the run needs PyBaMM's solver.
        """
        reason = self.engine_reason(values, extra_inputs, post, temperature_trace)
        if reason is not None:
            self.pybamm_reasons[reason] += 1
            return None
        cutoff_v = model_cutoff_v(float(cached_parameter_values(params)["Lower voltage cut-off [V]"]), obs,
                                  params.series)
        spm_params = engine_params(params, values, concentrations, post, cutoff_v)
        t_stop = float(obs.load.end_s) if t_end is None else min(float(t_end) + 3 * _EDGE_S, float(obs.load.end_s))
        request = SimulationRequest(load=obs.load.truncate(t_stop).shift_current(-offset_a),
                                    ambient_temperature_k=float(ambient_k), output_time_s=report_times(obs, t_end))
        reason = EngineSimulator.unsupported_reason(spm_params, request)
        if reason is not None:
            self.pybamm_reasons[reason] += 1
            return None
        assert self._spm is not None  # engine_reason says so
        try:
            res = self._spm.simulate(spm_params, request)
        except SimulationError as exc:
            self.pybamm_reasons[f"engine: {exc}"] += 1
            return None
        self.engine_runs += 1
        v_cells = list(np.asarray(res.extra["group_cell_voltage_v"], dtype=float))
        temp = None
        if want_temperature:
            temp = np.asarray(res.extra.get("cell_temperature_k", np.full(res.time_s.size, float(ambient_k))))
        return finish_run(params, obs, res.time_s, v_cells, temp, reached=res.reached_cutoff,
                          end_time_s=res.end_time_s, r_eq=self._r_eq(params, values), post=post, offset_a=offset_a,
                          cutoff_v=cutoff_v)

    @staticmethod
    def _r_eq(params: PackParams, values: dict) -> float:
        p = dict(params.interconnect)
        for k in INTERCONNECT_KEYS:
            if k in values:
                p[k] = float(values[k])
        return equivalent_network_resistance_ohm(params.series, params.parallel, p["r_b_ohm"], p["r_c_ohm"],
                                                 p["r_t_ohm"])

    def _result(self, params: PackParams, obs: Observed, sols: list[pybamm.Solution], t_end: float | None,
                r_eq: float, post: Post, offset_a: float, pv: pybamm.ParameterValues,
                want_temperature: bool) -> SimOut:
        t_all = report_times(obs, t_end)
        ends = [float(s.t[-1]) for s in sols]
        t_sol_end = min(ends)
        keep = np.minimum(t_all + 2 * _EDGE_S, obs.load.end_s - 2 * _EDGE_S) <= t_sol_end + 1e-9
        t_out = t_all[keep]
        t_eval = np.minimum(t_out + 2 * _EDGE_S, obs.load.end_s - 2 * _EDGE_S)
        v_cells = [np.asarray(s["Terminal voltage [V]"](t_eval), dtype=float) for s in sols]
        temp = None
        if want_temperature or post.series_activation_j_mol:
            temp = np.asarray(sols[0]["Volume-averaged cell temperature [K]"](t_eval), dtype=float)
        reached = any(s.termination and "Minimum voltage" in str(s.termination) for s in sols)
        cutoff_v = model_cutoff_v(float(pv["Lower voltage cut-off [V]"]), obs, params.series)
        return finish_run(params, obs, t_out, v_cells, temp, reached=reached, end_time_s=t_sol_end, r_eq=r_eq,
                          post=post, offset_a=offset_a, cutoff_v=cutoff_v)


def _evaluate_ocp(fn: Callable[..., Any] | tuple, sto: np.ndarray,
                  pv: pybamm.ParameterValues | None = None) -> np.ndarray:
    """An OCP of a PyBaMM parameter set (function of stoichiometry, or data) on ``sto``.

    ``pv`` (the parameter values) resolves parameters the function refers to (a measured OCP's
    coefficients, :mod:`battery_predictor.ocp`).
    """
    import inspect

    import pybamm

    if isinstance(fn, tuple):  # (name, (x, y)) data
        x, y = fn[1]
        return np.interp(sto, np.asarray(x, float).ravel(), np.asarray(y, float).ravel())
    if not callable(fn):
        raise SimulationError(f"unsupported OCP parameter {fn!r}")
    n_args = len(inspect.signature(fn).parameters)
    args = [pybamm.Vector(sto)] + [pybamm.Scalar(298.15)] * (n_args - 1)
    out = fn(*args)
    if isinstance(out, pybamm.Symbol) and pv is not None:
        out = pv.process_symbol(out)
    val = out.evaluate() if isinstance(out, pybamm.Symbol) else out
    return np.asarray(val, dtype=float).ravel()


def _solve_ocv(tables: tuple[np.ndarray, np.ndarray, np.ndarray], n_n: float, n_p: float, li: float, ocv_v: float) -> float:
    """Negative stoichiometry x at which U_p(y) - U_n(x) = ``ocv_v`` with n_n x + n_p y = li."""
    grid, u_n, u_p = tables
    lo = max(grid[0], (li - n_p * grid[-1]) / n_n)
    hi = min(grid[-1], (li - n_p * grid[0]) / n_n)
    if not lo < hi:
        raise SimulationError("the lithium inventory does not fit into the electrodes")
    x = np.linspace(lo, hi, 4001)
    y = (li - n_n * x) / n_p
    f = np.interp(y, grid, u_p) - np.interp(x, grid, u_n) - ocv_v
    sign = np.nonzero(np.diff(np.sign(f)) != 0)[0]
    if sign.size == 0:
        raise SimulationError(f"no state of the electrodes has an open-circuit voltage of {ocv_v:.3f} V")
    i = int(sign[0])
    return float(x[i] - f[i] * (x[i + 1] - x[i]) / (f[i + 1] - f[i]))


def _thickness_mappable(params: PackParams) -> bool:
    """Thickness folds into the volume fraction only in the isothermal SPM without options."""
    return params.model == "SPM" and not params.options and not params.extensions


def soc_from_voltage(engine: Engine, params: PackParams, cell_voltage_v: float) -> float:
    """SOC (0..1, params' window) whose open-circuit voltage is ``cell_voltage_v`` (0.5 when it fails)."""
    import pybamm

    try:
        pv = params.parameter_values()
        with quiet_pybamm():
            x, _ = pybamm.lithium_ion.get_initial_stoichiometries(f"{cell_voltage_v} V", pv)
        x0, x100, _, _ = engine.stoichiometry_window(params)
        soc = (float(x) - x0) / (x100 - x0)
        return float(min(max(soc, 0.0), 1.0)) if math.isfinite(soc) else 0.5
    except Exception:  # noqa: BLE001 - outside the OCV range: fall back
        return 0.5
