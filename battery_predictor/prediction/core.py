"""The predictor's logic without ROS: pack state, discharge-cycle average, runtime and routes.

The predictor node is a thin adapter around :class:`PredictorCore`: it feeds
clean pack states (from the battery monitor) with :meth:`PredictorCore.update_state`,
asks :meth:`PredictorCore.remaining_runtime` on a timer and
:meth:`PredictorCore.can_accept_route` from the service. Nothing here raises for
bad input or a failing model: every answer carries a status and a reason.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.params import DEFAULT_STANDSTILL_CURRENT_A, PackParams, load_params
from battery_predictor.prediction.calibration import Calibration, calibrate_on_history, history_segments
from battery_predictor.prediction.load_estimate import LoadEstimate, LoadEstimator, LoadKind, heavy_run_s
from battery_predictor.prediction.pack_model import PackModel, pack_model
from battery_predictor.prediction.priority import RoutePriority, YieldingRunner
from battery_predictor.prediction.route import RouteDecision, rejected
from battery_predictor.prediction.runtime import RuntimePrediction, predict_remaining_runtime, sampled_fraction_of
from battery_predictor.prediction.safety import (
    ChargeFloor,
    charge_floor,
    pulse_resistance_ohm,
    standstill_voltage_v,
    unexplained_jump_v,
)
from battery_predictor.prediction.temperature import (
    THERMAL_FORECASTS,
    AmbientEstimate,
    TemperatureAhead,
    plausible_temperature,
    temperature_ahead,
)
from battery_predictor.prediction.uncertainty import (
    LoadAhead,
    Spread,
    evaluate_route_at_risk,
    future_load_sigma,
    interval,
    ocv_band_soc_span,
    runtime_spread,
    uncertainty_model,
)
from battery_predictor.recording import DeepestState
from battery_predictor.simulation.cell_setup import is_lumped_thermal, with_thermal

if TYPE_CHECKING:
    from battery_predictor.profiles.ranger import RouteSection

# Status codes, identical to battery_predictor_msgs/RemainingRuntime constants.
STATUS_OK = 0
STATUS_STALE_INPUT = 1
STATUS_NO_INPUT = 2
STATUS_MODEL_NOT_FITTED = 3
STATUS_MODEL_FAILED = 4
STATUS_BELOW_CUTOFF = 5
STATUS_CHARGING = 6
STATUS_NO_LOAD = 7
STATUS_BEYOND_HORIZON = 8

#: Values of ``PredictorConfig.peak_source``.
PEAK_SOURCES = ("window", "sample")


@dataclass(frozen=True)
class PredictorConfig:
    """Settings of the predictor (copied from ROS parameters by the node).

    Attributes
    ----------
    params_file : str
        Fitted pack params YAML.
    cutoff_voltage_v : float
        Pack voltage at which the robot stops (runtime); NaN = from params thresholds.
    route_min_voltage_v : float
        Route acceptance threshold; NaN = from params thresholds.
    standstill_current_a : float
        Current the threshold applies at; NaN = from params thresholds.
    stale_after_s : float
        A pack state older than this is stale.
    charge_current_a : float
        A current below ``-charge_current_a`` charges the pack.
    charge_session_s : float
        Charging held this long (s) is a charging session: it ends the present discharge cycle.
        Shorter charging (regenerative braking, blips) stays part of the cycle.
    load_estimator : str
        ``"cycle"`` (mean net current of the present cycle, the paper's) or ``"ewma"``
        (exponentially weighted, ``load_time_constant_s``); see :mod:`.load_estimate`.
    load_time_constant_s : float
        Time constant of the ``"ewma"`` load estimator, s.
    load_model : str
        What of the average load stays constant ahead: ``"power"`` (the current rises as the pack
        voltage falls, as behind DC-DC converters and motor drives), ``"current"`` (the paper's),
        or ``"auto"`` (default): the cycle's own windows decide (:func:`.load_estimate.load_kind`),
        and while they cannot tell (random usage needs most of a discharge), the params' prior
        ``operating.load_prior_power_fraction`` (default 1, a constant power: it errs early, never
        late, on a current load; the Temi's params say 0, its usage model's constant-current states).
        Measured in docs/runtime_real_data: on the Panasonic drive cycles (constant power) MAE
        7.3 / 7.5 / 12.6 min for power / auto / current; on the emulated Temi bags (constant-current
        steps) 36.1 / 26.9 / 19.1 min.
    state_tolerance_v_per_cell : float
        Largest disagreement (V per series cell) between the propagated state's voltage and the
        measurement before the state is recalibrated; a fresh calibration still this far off
        rejects routes (the model cannot reproduce the pack).
    jump_tolerance_v_per_cell : float
        A voltage step between two windows beyond this (V per series cell, plus twice what the
        current step explains) is a new pack state (battery swap): history before it is dropped.
    default_temperature_k : float
        Temperature used when none is measured; NaN = params ambient.
    route_currents_file : str
        Ranger per-(payload, slope) current samples (empty = shipped default).
    calibration_window_s : float
        History the SOC calibration simulates (0 = calibrate on the latest sample only, as the paper).
    peak_current_quantile : float
        Quantile of the present cycle's (5 s window) currents taken as its recurring load peak:
        the robot stops at the first measured window below the cut-off, which falls on a load peak,
        not on the average load; the runtime ends when a peak drawn from the average-load
        trajectory reaches the cut-off (0 = average only, as the paper). Default 0.99 (a load
        drawn 1 % of the time); on the bundled Temi bags it cut the runtime MAE from 38.4 to
        23.6 min (docs/evaluation).
    peak_source : str
        ``"window"``: the peak is a quantile of the 5 s window means and lasts a window (the robot
        stops on a window below its cut-off); ``"sample"``: a quantile of each window's largest
        sample current, lasting ``peak_duration_s`` (the robot, or the test equipment, stops on
        the first sample below the cut-off).
    peak_duration_s : float
        How long a sample peak lasts in the model, s (``peak_source = "sample"``).
    simulator : str
        ``"auto"`` (the SPM engine unless the params activate extensions), ``"engine"`` or
        ``"pybamm"`` (PyBaMM's solver stepped segment by segment); see :mod:`.pack_model`.
    recalibrate_after_s : float
        Between full calibrations (at most this far apart, s) the calibrated state is propagated
        with the measured current (charge counting through the model), which is more reliable
        than a voltage calibration under load on a flat OCV (LiFePO4).
    drift_correction : str
        What a carried state that left ``state_tolerance_v_per_cell`` is moved to: ``"full"`` (a fresh calibration
        onto the measured voltage), ``"smallest"`` (a calibration that leaves half the tolerance on the side the
        state left: the smallest correction consistent with the measurement; never against that side, see
        :data:`KEPT_DRIFT_TOLERANCES`), or ``"auto"`` (default):
        ``"smallest"`` where the OCVs within the tolerance of the state's span more than :data:`FLAT_OCV_SOC_SPAN` of
        the capacity, ``"full"`` elsewhere (and where the model gives no OCV). Where the OCV is flat
        (LiFePO4's plateau) a voltage the model misses by the tolerance is a large part of the charge and says
        little about the state. Measured (docs/runtime_real_data/other_cells.md): the fit recordings of three cells
        tie (pooled MAE 3.65 full / 3.72 smallest min); held out, K2 LiFePO4 7.5 -> 3.8 min, LG M50 6.9 -> 7.1.
    end_event : str
        Where the runtime of a load with peaks ends: ``"peak"`` where a peak at ``peak_current_quantile`` drawn
        at any moment would reach the cut-off; ``"sampled"`` at the median end of futures resampled in 10 min
        blocks from the cycle's own windows (:func:`.runtime.sampled_end_s`), the first load state heavy enough
        at that charge; ``"auto"`` (default): ``"sampled"`` where the windows resolve the load's states (the
        cycle's heavy windows come in runs of :data:`RESOLVED_STATE_S` and :data:`RESOLVED_STATE_WINDOWS` windows
        or more on average), ``"peak"`` where the load changes within a window or two (a drive cycle: its
        sub-window spikes end the discharge, and futures of window means would miss them). The futures run at
        most every :data:`SAMPLED_REFRESH_S` of pack-state time; in between an answer keeps the last one's place
        between the peak-load and the average-load crossings.
    thermal_forecast : str
        ``"auto"`` (default): when the params carry a lumped thermal cell that the engine runs, the runtime
        forecast starts the cells at the latest measured temperature and integrates it with that cell's heat
        equation (heat from the load, exchange with ``ambient_temperature_k``); otherwise the forecast holds
        the latest measured temperature. ``"held"``: the params' cell is made isothermal (PyBaMM's option) and
        every run holds the latest measured temperature. See :mod:`.temperature`.
    ambient_temperature_k : float
        Ambient temperature of a self-heating forecast, K; NaN (default) = the lowest cell temperature measured
        since the present discharge cycle began (:class:`.temperature.AmbientEstimate`).
    decision_risk : float
        Accepted probability that the pack ends a route (or a task and the walk back to the
        charger) below its threshold (0 < risk <= 0.5): accepted when the voltage the pack stays
        above with probability ``1 - risk`` is at or above the threshold (default 0.1: the P10
        voltage). 0.5 decides on the P50 voltage, as the paper. See :mod:`.uncertainty`.
    """

    params_file: str
    cutoff_voltage_v: float = math.nan
    route_min_voltage_v: float = math.nan
    standstill_current_a: float = math.nan
    stale_after_s: float = 30.0
    charge_current_a: float = 0.2
    charge_session_s: float = 300.0
    load_estimator: str = "cycle"
    load_time_constant_s: float = 1800.0
    load_model: str = "auto"
    state_tolerance_v_per_cell: float = 0.05
    jump_tolerance_v_per_cell: float = 0.1
    default_temperature_k: float = math.nan
    route_currents_file: str = ""
    calibration_window_s: float = 600.0
    recalibrate_after_s: float = 3600.0
    peak_current_quantile: float = 0.99
    peak_source: str = "window"
    peak_duration_s: float = 1.0
    simulator: str = "auto"
    decision_risk: float = 0.1
    drift_correction: str = "auto"
    end_event: str = "auto"
    thermal_forecast: str = "auto"
    ambient_temperature_k: float = math.nan


#: What of the average load the runtime keeps constant (``PredictorConfig.load_model``).
LOAD_MODELS = ("auto", "power", "current")
#: Where a carried state that left the tolerance band goes (``PredictorConfig.drift_correction``).
DRIFT_CORRECTIONS = ("auto", "full", "smallest")
#: ``drift_correction "auto"`` corrects a drifted state by the smallest step where the OCVs within the state
#: tolerance span more than this share of the capacity (:func:`~.uncertainty.ocv_band_soc_span`; shipped NMC params:
#: 0.1-0.18 between 10 and 90 % SOC; LiFePO4: 0.45-0.85 on its plateaus, 0.2-0.3 at their ends).
FLAT_OCV_SOC_SPAN = 0.3
#: A ``"smallest"`` drift correction that would move the state of charge against the carried state's residual
#: keeps the carried state while its residual is within this many state tolerances; beyond, the state is calibrated
#: onto the measurement (the voltage has the last word).
KEPT_DRIFT_TOLERANCES = 2.0
#: Where the runtime of a load with peaks ends (``PredictorConfig.end_event``).
END_EVENTS = ("auto", "peak", "sampled")
#: ``end_event "auto"`` takes ``"sampled"`` where the cycle's heavy windows (at or above this quantile of its
#: discharge windows) come in runs of at least :data:`RESOLVED_STATE_S` on average
#: (:func:`~.load_estimate.heavy_run_s`), else ``"peak"``.
HEAVY_WINDOW_QUANTILE = 0.9
#: Mean heavy run (s) from which the windows resolve the load's states. Measured on data: drive cycles
#: (Panasonic 18650PF, 11 files) 7-11 s, constant currents and HPPC pulses 5-8 s; a Temi's random usage 12-54 s,
#: the Ranger's routes 14-63 s.
RESOLVED_STATE_S = 15.0
#: ... and at least this many windows, whatever the monitor's window length.
RESOLVED_STATE_WINDOWS = 3
#: How long (s of pack-state time) a ``"sampled"`` answer's place between the peak-load and the average-load
#: crossings is reused before its futures are run again (the cycle's load statistics change slowly; the futures
#: take about a second).
SAMPLED_REFRESH_S = 900.0
#: Exponent of the ``"auto"`` load model while the cycle's data cannot tell current from power, unless the
#: params say otherwise (:data:`LOAD_PRIOR_KEY`): a constant power errs early, never late, on a current load.
AUTO_LOAD_PRIOR = 1.0
#: ``operating`` key of a params file: the robot's load as a power fraction (1 = constant power, 0 = constant
#: current) that the ``"auto"`` load model assumes until the cycle's windows decide.
LOAD_PRIOR_KEY = "load_prior_power_fraction"


def _load_text(current_a: float, power_w: float | None, kind: LoadKind, now_a: float) -> str:
    """How a runtime reason names its load: ``"1.25 A"``, ``"4.8 W (now 1.30 A)"`` or a mix."""
    if power_w is None:
        return f"{current_a:.2f} A"
    if kind.exponent >= 1.0:
        return f"{power_w:.1f} W (now {now_a:.2f} A)"
    return f"{current_a:.2f} A / {power_w:.1f} W, load exponent {kind.exponent:.2f} (now {now_a:.2f} A)"


@dataclass(frozen=True)
class _LoadView:
    """The present cycle's load as one runtime answer uses it (A, W, s; read once under the core's lock)."""

    load: LoadEstimate
    peak_a: float
    kind: LoadKind
    cycle: int
    sampled_fraction: float | None
    history_a: np.ndarray | None  # the cycle's window currents when the futures run again, else None
    window_s: float
    end_event: str
    power_w: float | None  # the mean power when the load model ahead is (partly) a power, else None


def _runtime_refusal(stamp_s: float, voltage_v: float, cutoff_v: float, load: LoadEstimate,
                     temperature_k: float) -> RuntimeStatus | None:
    """The invalid answer for a pack at its cut-off, charging, or without a discharge load (else None)."""
    if voltage_v <= cutoff_v:
        return _invalid_runtime(stamp_s, cutoff_v, STATUS_BELOW_CUTOFF,
                                f"pack voltage {voltage_v:.2f} V is at or below the cut-off {cutoff_v:.2f} V",
                                remaining_s=0.0, temperature_k=temperature_k)
    if load.charging:
        return _invalid_runtime(stamp_s, cutoff_v, STATUS_CHARGING, f"charging at {-load.charging_current_a:.2f} A",
                                temperature_k=temperature_k)
    avg = load.mean_current_a
    if not (math.isfinite(avg) and avg > 0):
        what = "no discharge measured yet" if not math.isfinite(avg) else f"net load {avg:.3f} A"
        return _invalid_runtime(stamp_s, cutoff_v, STATUS_NO_LOAD,
                                f"no discharge load in the present cycle to predict from ({what})",
                                temperature_k=temperature_k)
    return None


def _peaks_text(pred: RuntimePrediction, peak_a: float) -> str:
    """How a runtime reason names the end event: the peaks it assumed, or the resampled load."""
    if pred.limited_by == "peak_cutoff":
        return f" with {peak_a:.2f} A peaks"
    return " with the cycle's load resampled" if pred.limited_by == "sampled_cutoff" else ""


def _heating_text(ahead: TemperatureAhead, pred: RuntimePrediction) -> str:
    """The self-heating note of a runtime reason (empty when the temperature ahead is held)."""
    if not ahead.self_heating:
        return ""
    end_k = pred.end_temperature_k
    return f" ({ahead.note}; {end_k - 273.15:.1f} degC at the end)" if math.isfinite(end_k) else f" ({ahead.note})"


@dataclass(frozen=True)
class RuntimeStatus:
    """What ``/remaining_runtime`` publishes (see RemainingRuntime.msg)."""

    stamp_s: float
    remaining_s: float
    assumed_current_a: float
    assumed_temperature_k: float
    state_of_charge: float
    cutoff_voltage_v: float
    valid: bool
    status: int
    reason: str
    remaining_p10_s: float = math.nan
    remaining_p90_s: float = math.nan
    spread: Spread | None = None


#: Floor of the calibrated state's voltage error, V per series cell (a voltage sensor's resolution).
STATE_VOLTAGE_FLOOR_V_PER_CELL = 0.005


class PredictorCore:
    """State and answers of the predictor (thread-safe).

    Parameters
    ----------
    config : PredictorConfig
        Settings.
    params : PackParams, optional
        Already loaded params (otherwise read from ``config.params_file``).
    """

    def __init__(self, config: PredictorConfig, params: PackParams | None = None) -> None:
        self.config = config
        self._lock = threading.Lock()
        self._state: tuple[float, float, float, float] | None = None
        #: Lowest cell (series-group) voltage measured in the latest state's window (V; NaN: not measured).
        self._min_cell_voltage_v = math.nan
        self._cell_cutoff_v: float | None = None
        self._history: deque[tuple[float, float, float, float]] = deque()
        self._cal_lock = threading.Lock()
        # (stamp, full-calibration stamp, cal) per kind: False the runs at the measured temperature (routes, and
        # the forecast of an isothermal cell), True a self-heating forecast's (cells at the measured temperatures)
        self._cals: dict[bool, tuple[float, float, Calibration]] = {}
        if config.drift_correction not in DRIFT_CORRECTIONS:
            raise ValueError(f"drift_correction {config.drift_correction!r} is not one of "
                             f"{', '.join(DRIFT_CORRECTIONS)}")
        if config.end_event not in END_EVENTS:
            raise ValueError(f"end_event {config.end_event!r} is not one of {', '.join(END_EVENTS)}")
        #: (pack-state stamp s, discharge cycles ended, place between the crossings) of the last sampled futures
        self._sampled: tuple[float, int, float] | None = None
        if config.thermal_forecast not in THERMAL_FORECASTS:
            raise ValueError(f"thermal_forecast {config.thermal_forecast!r} is not one of {', '.join(THERMAL_FORECASTS)}")
        #: Lowest cell temperature measured since the present discharge cycle began (the ambient estimate).
        self._ambient = AmbientEstimate()
        if config.load_model not in LOAD_MODELS:
            raise ValueError(f"load_model {config.load_model!r} is not one of {', '.join(LOAD_MODELS)}")
        if not 0.0 < config.decision_risk <= 0.5:
            raise ValueError(f"decision_risk must be in (0, 0.5], got {config.decision_risk}")
        self._load = self._fresh_load_estimator()
        #: Why the next calibration must start afresh ("" = it may continue the last one).
        self._recalibrate_reason = ""
        self._drifted: Calibration | None = None  # the last carried state that left the tolerance band
        self.events: deque[tuple[float, str]] = deque(maxlen=100)
        self.model_error = ""
        self.params: PackParams | None = None
        self.runner: PackModel | None = None
        #: Which pack model answers, and why (engine or PyBaMM stepping).
        self.model_backend = ""
        #: Route answers in progress: a runtime update's model runs wait for them (:mod:`.priority`).
        self.route_priority = RoutePriority()
        try:
            self.params = params or load_params(Path(config.params_file))
            if config.thermal_forecast == "held" and is_lumped_thermal(self.params):
                # held means held: the same cell, isothermal at the latest measured temperature
                self.params = with_thermal(self.params, "isothermal")
            self.runner, self.model_backend = pack_model(self.params, config.simulator)
        except BatteryPredictorError as exc:
            self.model_error = str(exc)
        th = self.params.thresholds if self.params else {}
        self.cutoff_voltage_v = _pick(config.cutoff_voltage_v, th.get("runtime_cutoff_voltage_v"),
                                      self.params.pack_info.get("min_voltage_v") if self.params else None)
        self.route_min_voltage_v = _pick(config.route_min_voltage_v, th.get("route_min_voltage_v"))
        self.standstill_current_a = _pick(config.standstill_current_a, th.get("standstill_current_a"),
                                          DEFAULT_STANDSTILL_CURRENT_A)
        self.default_temperature_k = _pick(config.default_temperature_k,
                                           self.params.ambient_temperature_k if self.params else None, 298.15)
        series = self.params.series if self.params else 1
        self.uncertainty = uncertainty_model(self.params.provenance if self.params else {}, series,
                                             self.default_temperature_k if not self.params
                                             else self.params.ambient_temperature_k)
        #: Exponent of the ``"auto"`` load model while the cycle's windows cannot tell current from power.
        self.load_kind_prior = float(self.params.operating.get(LOAD_PRIOR_KEY, AUTO_LOAD_PRIOR)) if self.params \
            else AUTO_LOAD_PRIOR
        self.state_tolerance_v = config.state_tolerance_v_per_cell * series
        self.jump_tolerance_v = config.jump_tolerance_v_per_cell * series
        self._resistance_cache: dict[int, float] = {}
        #: The routes' charge floor from the fit data's deepest state, once computed (a 1-tuple; None: not yet).
        self._floor: tuple[ChargeFloor | None] | None = None
        self.resistance_ohm = self._resistance(self.default_temperature_k) if self.runner is not None else math.nan
        self._currents = None
        if config.route_currents_file:
            from battery_predictor.profiles.ranger import load_ranger_currents

            try:
                self._currents = load_ranger_currents(config.route_currents_file)
            except BatteryPredictorError as exc:
                self.model_error = self.model_error or str(exc)

    def _fresh_load_estimator(self) -> LoadEstimator:
        """An empty load estimator of this core's settings."""
        cfg = self.config
        return LoadEstimator(cfg.charge_current_a, cfg.charge_session_s, cfg.load_estimator, cfg.load_time_constant_s)

    def _resistance(self, temperature_k: float) -> float:
        """The pack's 5 s pulse resistance at ``temperature_k`` (cached per kelvin; NaN when the model fails)."""
        key = round(temperature_k)
        if key not in self._resistance_cache:
            try:
                self._resistance_cache[key] = pulse_resistance_ohm(self._runner(), float(key))
            except BatteryPredictorError:
                self._resistance_cache[key] = math.nan
        return self._resistance_cache[key]

    # ----------------------------------------------------------------- input
    def update_state(self, stamp_s: float, voltage_v: float, current_a: float, temperature_k: float,
                     peak_current_a: float = math.nan, min_cell_voltage_v: float = math.nan) -> None:
        """Take a clean pack state (V, A positive = discharge, K or NaN) stamped ``stamp_s``.

        ``peak_current_a`` is the window's largest sample current (A; NaN when unknown);
        ``min_cell_voltage_v`` its lowest measured cell (series-group) voltage (V; NaN when not
        measured), which only the route check reads (:meth:`can_accept_route`).
        """
        if not (math.isfinite(stamp_s) and math.isfinite(voltage_v) and math.isfinite(current_a)):
            return
        with self._lock:
            previous = self._state
            if previous is not None and stamp_s <= previous[0]:
                return
            self._state = (stamp_s, voltage_v, current_a, temperature_k)
            self._min_cell_voltage_v = float(min_cell_voltage_v)
            was_charging = self._load.in_session
            if self._load.add(stamp_s, current_a, peak_current_a, voltage_v):
                self._new_state(stamp_s, "a charging session began")
            elif was_charging and not self._load.in_session:
                self._new_state(stamp_s, "the charging session ended")
            if previous is not None and self._is_jump(previous, self._state):
                self._history.clear()
                self._new_state(stamp_s, f"voltage jumped {previous[1]:.2f} -> {voltage_v:.2f} V at "
                                         f"{previous[2]:.2f} -> {current_a:.2f} A, more than the current explains "
                                         "(battery swap, sensor, or the end-of-discharge knee): calibrating afresh")
            self._ambient.add(temperature_k)
            self._history.append(self._state)
            horizon = max(self.config.calibration_window_s, self.config.recalibrate_after_s, 60.0) + 300.0
            while self._history and self._history[0][0] < stamp_s - horizon:
                self._history.popleft()

    def _is_jump(self, previous: tuple, latest: tuple) -> bool:
        r_ohm = self.resistance_ohm if math.isfinite(self.resistance_ohm) else 0.0
        allowed = self.jump_tolerance_v + 2.0 * abs(latest[2] - previous[2]) * r_ohm
        return unexplained_jump_v(previous[1:3], latest[1:3], r_ohm) > allowed

    def _new_state(self, stamp_s: float, why: str) -> None:
        """Forget the calibrated state: the next answer calibrates afresh (caller holds ``_lock``)."""
        self._recalibrate_reason = why
        self.events.append((stamp_s, why))
        self._ambient.reset()
        self._sampled = None  # a new pack: its sampled answer is placed afresh

    def latest_state(self) -> tuple[float, float, float, float] | None:
        """(stamp_s, voltage_v, current_a, temperature_k) of the latest state, or None."""
        with self._lock:
            return self._state

    def _measured_cell_below_cutoff(self) -> str:
        """Why the latest state's lowest measured cell voltage forbids a route ("" when it does not, or none was
        measured): it is at or below the cell's lower cut-off voltage of the params."""
        with self._lock:
            v_cell = self._min_cell_voltage_v
        if not math.isfinite(v_cell) or self.params is None:
            return ""
        if self._cell_cutoff_v is None:
            try:
                self._cell_cutoff_v = self.params.cell_lower_cutoff_v
            except (BatteryPredictorError, KeyError, ValueError):
                self._cell_cutoff_v = math.nan
        cutoff = self._cell_cutoff_v
        if math.isfinite(cutoff) and v_cell <= cutoff:
            return (f"measured minimum cell voltage {v_cell:.3f} V is already at or below the cell's lower cut-off "
                    f"{cutoff:.2f} V (params)")
        return ""

    def _runner(self) -> PackModel:
        """The pack model (raises when no params file could be loaded; answers check ``_usable_state`` first)."""
        if self.runner is None:
            raise BatteryPredictorError(f"no usable pack model: {self.model_error}")
        return self.runner

    def _usable_state(self, now_s: float) -> tuple[int, str, tuple[float, float, float, float] | None]:
        if self.runner is None:
            return STATUS_MODEL_NOT_FITTED, f"no usable pack model: {self.model_error}", None
        state = self.latest_state()
        if state is None:
            return STATUS_NO_INPUT, "no pack state received yet", None
        age = now_s - state[0]
        if age > self.config.stale_after_s:
            return STATUS_STALE_INPUT, f"pack state is stale ({age:.1f} s old, limit {self.config.stale_after_s:.0f} s)", state
        return STATUS_OK, "", state

    def calibration(self, temperature_k: float, ahead: TemperatureAhead | None = None) -> Calibration:
        """Calibrated present state (cached; propagated between full calibrations).

        The state is carried forward with the measured current between full calibrations while
        its voltage stays within ``state_tolerance_v`` of the measurement; otherwise, after a
        jump or a charging session, or after ``recalibrate_after_s``, it is calibrated afresh.

        With a self-heating ``ahead`` (a lumped thermal cell, :mod:`.temperature`) the runs over the history
        start the cells at the temperature measured where each run starts and take ``ahead``'s ambient, a
        state of its own (the runtime forecast's); otherwise every run takes ``temperature_k`` (the routes'
        state, unchanged by the thermal forecast).

        Raises
        ------
        BatteryPredictorError
            When the model fails.
        """
        heating = ahead if ahead is not None and ahead.self_heating else None
        with self._cal_lock:
            with self._lock:
                hist = list(self._history)
                if self._recalibrate_reason:  # a new pack state: the cached one must never be continued
                    self._cals.clear()
                    self._recalibrate_reason = ""
            if not hist:
                raise BatteryPredictorError("no pack state to calibrate on")
            stamp = hist[-1][0]
            cached = self._cals.get(heating is not None)
            if cached is not None and cached[0] == stamp:
                return cached[2]
            # a state clipped above full is carried as well: the cell cannot hold more than the model's top, so the
            # charge drawn since bounds it from above, while a fresh calibration would put it back at the top
            # minus the calibration window's charge on every window (a flat-OCV LiFePO4 cell above the model's
            # voltage answered the same runtime for half a discharge)
            if (cached is not None and cached[2].state is not None and cached[2].clipped in ("", "above_full")
                    and stamp - cached[1] < self.config.recalibrate_after_s and stamp > cached[0]):
                propagated = self._propagate(cached, hist, temperature_k, heating)
                if propagated is not None:
                    return propagated
                if self._drifted is not None and self._corrects_smallest(cached[2].soc, temperature_k):
                    return self._correct_smallest(cached, self._drifted, hist, temperature_k, heating)
            return self._calibrate_fresh(hist, temperature_k, heating)

    def _correct_smallest(self, cached: tuple[float, float, Calibration], carried: Calibration,
                          hist: list[tuple[float, float, float, float]], temperature_k: float,
                          heating: TemperatureAhead | None) -> Calibration:
        """The drifted state moved back just inside the tolerance band, on the side it left.

        Half the band, not onto the measurement: where the OCV is flat (LiFePO4's plateau) a voltage the model
        misses by the tolerance is a large part of the charge. A calibration that moves the state of charge
        against its residual's side (less charge where the model's voltage is below the measurement, or more
        where it is above) answers a different question than the one that triggered it: the window's fit trades
        the carried particles' gradients for charge, or its mean voltage lags a falling measurement. Then the
        carried state is kept, with its residual, which keeps routes rejected until the state agrees with the
        measurement again; up to :data:`KEPT_DRIFT_TOLERANCES` tolerances, beyond which the state is calibrated
        onto the measurement.
        """
        drift_v = carried.latest_residual_v
        target = math.copysign(0.5 * self.state_tolerance_v, drift_v)
        fresh = self._calibrate_fresh(hist, temperature_k, heating, target_residual_v=target)
        if fresh.clipped or (fresh.soc - carried.soc) * drift_v <= 0.0:
            return fresh
        if abs(drift_v) > KEPT_DRIFT_TOLERANCES * self.state_tolerance_v:
            return self._calibrate_fresh(hist, temperature_k, heating)
        with self._lock:
            self.events.append((hist[-1][0], f"recalibration moved the SOC {carried.soc:.3f} -> {fresh.soc:.3f}, "
                                              f"against the residual {drift_v:+.2f} V: carried state kept"))
        self._cals[heating is not None] = (hist[-1][0], cached[1], carried)
        return carried

    def _corrects_smallest(self, soc: float, temperature_k: float) -> bool:
        """Whether a drifted state at ``soc`` moves just inside the tolerance band (``drift_correction``)."""
        if self.config.drift_correction != "auto":
            return self.config.drift_correction == "smallest"
        span = ocv_band_soc_span(self._runner(), soc, self.state_tolerance_v, temperature_k)
        return span > FLAT_OCV_SOC_SPAN

    def precalibrate(self) -> None:
        """Calibrate the latest pack state now, at its temperature, so the next answers find it cached.

        Called when a pack state arrives (the node's state callback), so a route answer does not
        calibrate; a self-heating forecast's state (:meth:`calibration` with its ``ahead``) is carried
        too. Never raises: an answer that needs the calibration meets the failure again and
        reports it.
        """
        state = self.latest_state()
        if self.runner is None or state is None:
            return
        try:
            temperature_k = self._temperature(state[3])
            self.calibration(temperature_k)
            ahead = self.temperature_ahead(temperature_k)
            if ahead.self_heating:  # the runtime forecast's own state, carried window by window as the routes'
                self.calibration(temperature_k, ahead)
        except BatteryPredictorError:
            pass

    def _propagate(self, cached: tuple[float, float, Calibration], hist: list[tuple[float, float, float, float]],
                   temperature_k: float, heating: TemperatureAhead | None = None) -> Calibration | None:
        """The cached state carried to now by the measured current, or None when it left the measurement
        (then ``_drifted`` holds that state, with its residual, else None)."""
        self._drifted = None
        newer = [h for h in hist if h[0] >= cached[0]]
        if len(newer) < 2:
            return None
        t = np.array([h[0] for h in newer])
        i = np.array([h[2] for h in newer])
        segs = history_segments(t, i, max_segments=min(120, len(newer) - 1))
        start = cached[2].state
        if start is None:
            return None
        if heating is not None:  # from the temperature measured where the carried state stands, in the ambient
            start = self._runner().at_cell_temperature(start, self._temperature(newer[0][3]))  # type: ignore[attr-defined]
            temperature_k = heating.ambient_k
        run = self._runner().run(start, segs, temperature_k)
        if run.final_state is None or run.reached_cutoff:
            return None
        residual = float(run.pack_voltage_v[-1]) - hist[-1][1]
        # carried from above full, a model voltage below the measurement is what clipped the state: the
        # measurement asks for more charge than the model holds, charge counting is the bound
        still_above = cached[2].clipped == "above_full" and residual < -self.state_tolerance_v
        cal = Calibration(self._runner().soc_of(run.final_state), residual, "above_full" if still_above else "",
                          run.final_state, residual)
        if abs(residual) > self.state_tolerance_v and not still_above:
            with self._lock:
                self.events.append((hist[-1][0], f"propagated state {residual:+.2f} V off the measurement: "
                                                  "recalibrated"))
            self._drifted = cal
            return None
        self._cals[heating is not None] = (hist[-1][0], cached[1], cal)
        return cal

    def _calibrate_fresh(self, hist: list[tuple[float, float, float, float]], temperature_k: float,
                         heating: TemperatureAhead | None = None, *, target_residual_v: float = 0.0) -> Calibration:
        t = np.array([h[0] for h in hist])
        v = np.array([h[1] for h in hist])
        i = np.array([h[2] for h in hist])
        window = self.config.calibration_window_s
        runner = self._runner()
        cell_k = None
        if heating is not None:  # the window's runs start at the temperature measured there, in the ambient
            first = int(np.searchsorted(t, t[-1] - max(window, 1.0))) if window > 0 else len(hist) - 1
            cell_k, temperature_k = self._temperature(hist[first][3]), heating.ambient_k
        cal = calibrate_on_history(runner, t, v, i, temperature_k, window_s=max(window, 1.0),
                                   target_residual_v=target_residual_v, cell_temperature_k=cell_k) if window > 0 \
            else calibrate_on_history(runner, t[-1:], v[-1:], i[-1:], temperature_k, cell_temperature_k=cell_k)
        self._cals[heating is not None] = (t[-1], t[-1], cal)
        return cal

    def _peak_duration_s(self) -> float:
        return self.config.peak_duration_s if self.config.peak_source == "sample" else 5.0

    def _end_event(self, stamps_s: np.ndarray, currents_a: np.ndarray, window_s: float) -> str:
        """The end event of the present answer: the configured one, or ``"auto"``'s choice from the cycle's windows
        (stamps in s, currents in A, ``window_s`` their length in s)."""
        if self.config.end_event != "auto":
            return self.config.end_event
        run_s = heavy_run_s(stamps_s, currents_a, HEAVY_WINDOW_QUANTILE, window_s)
        return "sampled" if run_s >= max(RESOLVED_STATE_S, RESOLVED_STATE_WINDOWS * window_s) else "peak"

    def _temperature(self, temperature_k: float) -> float:
        return temperature_k if plausible_temperature(temperature_k) else self.default_temperature_k

    def temperature_ahead(self, cell_temperature_k: float) -> TemperatureAhead:
        """How the forecast from a cell at ``cell_temperature_k`` (K) treats the temperature ahead (:mod:`.temperature`)."""
        stated = self.config.ambient_temperature_k
        if plausible_temperature(stated):
            ambient, source = stated, "stated"
        else:
            with self._lock:
                ambient = self._ambient.value_k
            source = "the lowest cell temperature measured in this discharge cycle"
        return temperature_ahead(self._runner(), cell_temperature_k, ambient, self.config.thermal_forecast,
                                 ambient_source=source)

    # --------------------------------------------------------------- answers
    def remaining_runtime(self, now_s: float) -> RuntimeStatus:
        """Remaining runtime until the cut-off under the present cycle's load (never raises for bad input)."""
        status, reason, state = self._usable_state(now_s)
        cutoff = self.cutoff_voltage_v
        if status != STATUS_OK or state is None:
            return _invalid_runtime(now_s, cutoff, status, reason)
        stamp, v, i, t_k = state
        temp = self._temperature(t_k)
        view = self._load_view(stamp, temp)
        refusal = _runtime_refusal(stamp, v, cutoff, view.load, temp)
        if refusal is not None:
            return refusal
        try:
            ahead, pred = self._forecast(v, i, temp, view)
        except BatteryPredictorError as exc:
            return _invalid_runtime(stamp, cutoff, STATUS_MODEL_FAILED, f"model failed: {exc}", temperature_k=temp)
        placed = sampled_fraction_of(pred) if view.sampled_fraction is None else None
        if placed is not None:
            with self._lock:
                self._sampled = (stamp, view.cycle, placed)
        return self._runtime_answer(stamp, v, temp, view, ahead, pred)

    def _load_view(self, stamp_s: float, temperature_k: float) -> _LoadView:
        """The present cycle's load as the runtime answer at ``stamp_s`` (s) uses it, read under the lock."""
        r_ohm = self._resistance(temperature_k) if self.config.load_model == "auto" else math.nan
        with self._lock:
            load = self._load.estimate()
            peak = self._load.quantile_a(self.config.peak_current_quantile,
                                         of_peaks=self.config.peak_source == "sample")
            kind = self._load_kind(r_ohm)
            cycle = self._load.sessions_ended
            reused = self._sampled
            fraction = (reused[2] if reused is not None and reused[1] == cycle
                        and 0.0 <= stamp_s - reused[0] < SAMPLED_REFRESH_S else None)
            windows = self.config.end_event == "auto" or (self.config.end_event == "sampled" and fraction is None)
            history_a = np.fromiter(self._load.currents, float) if windows else np.empty(0)
            stamps = np.fromiter(self._load.stamps, float) if windows else np.empty(0)
        window_s = float(np.median(np.diff(stamps))) if stamps.size > 1 else 5.0
        end_event = self._end_event(stamps, history_a, window_s)
        # the futures need the cycle's windows only when they run again
        resample = end_event == "sampled" and fraction is None
        mean_power_w = load.mean_power_w if kind.exponent > 0 else math.nan
        power = mean_power_w if math.isfinite(mean_power_w) and mean_power_w > 0 else None
        return _LoadView(load, peak, kind, cycle, fraction, history_a if resample else None, window_s, end_event,
                         power)

    def _forecast(self, voltage_v: float, current_a: float, temperature_k: float,
                  view: _LoadView) -> tuple[TemperatureAhead, RuntimePrediction]:
        """The temperature ahead and the runtime prediction from a fresh calibration (raises on model failure)."""
        ahead = self.temperature_ahead(temperature_k)
        cal = self.calibration(temperature_k, ahead)
        if ahead.self_heating:  # the cells start at the measured temperature and warm (or cool) from there
            started = ahead.start(self._runner(), cal.start)
            cal = replace(cal, state=started) if not isinstance(started, float) else cal
        peak = view.peak_a
        pred = predict_remaining_runtime(self._background_runner(), voltage_v, current_a, ahead.run_temperature_k,
                                         view.load.mean_current_a, self.cutoff_voltage_v, calibration=cal,
                                         peak_current_a=peak if math.isfinite(peak) else None,
                                         peak_duration_s=self._peak_duration_s(), average_power_w=view.power_w,
                                         load_exponent=view.kind.exponent, end_event=view.end_event,
                                         load_history_a=view.history_a,
                                         history_window_s=min(max(view.window_s, 0.1), 60.0),
                                         sampled_fraction=view.sampled_fraction)
        return ahead, pred

    def _runtime_answer(self, stamp_s: float, voltage_v: float, temperature_k: float, view: _LoadView,
                        ahead: TemperatureAhead, pred: RuntimePrediction) -> RuntimeStatus:
        """The published answer of ``pred``: SOC, P10..P90, status and the reason a reader sees."""
        load, kind, cutoff = view.load, view.kind, self.cutoff_voltage_v
        avg = load.mean_current_a
        soc, soc_note = published_soc(pred.calibration.soc)
        notes = [n for n in (soc_note, f"calibration {pred.calibration.clipped}" if pred.calibration.clipped else "")
                 if n]
        undecided = (0.0 if kind.exponent >= 0.5 else 1.0) if self.config.load_model == "auto" and not kind.decided \
            else None
        mean_power = load.mean_power_w if math.isfinite(load.mean_power_w) and load.mean_power_w > 0 else 0.0
        spread = self._runtime_spread(pred, LoadAhead(avg, mean_power, kind.exponent if view.power_w else 0.0,
                                                      math.nan, undecided), voltage_v)
        note = "; " + "; ".join(notes) if notes else ""
        load_text = _load_text(avg, view.power_w, kind, pred.assumed_current_a)
        if pred.limited_by == "horizon":
            return RuntimeStatus(stamp_s, pred.remaining_s, avg, temperature_k, soc, cutoff, False,
                                 STATUS_BEYOND_HORIZON, f"more than {pred.remaining_s / 60:.0f} min at {load_text} "
                                 f"(the longest horizon simulated){note}")
        if pred.limited_by == "peak_cutoff" and pred.remaining_s == 0.0:
            note = f"; a {view.peak_a:.2f} A load peak now would reach the cut-off{note}"
        p10, p90 = interval(pred.remaining_s, *spread.total()) if spread is not None else (math.nan, math.nan)
        band = f" (P10..P90 {p10 / 60:.1f}..{p90 / 60:.1f} min)" if spread is not None else ""
        until = (f"a cell reaches its {self.params.cell_lower_cutoff_v:.2f} V cut-off (pack above {cutoff:.2f} V)"
                 if pred.cell_limited and self.params is not None else f"{cutoff:.2f} V")
        reason = (f"{pred.remaining_s / 60:.1f} min{band} at {load_text}{_peaks_text(pred, view.peak_a)}, "
                  f"{temperature_k - 273.15:.1f} degC{_heating_text(ahead, pred)} until {until} "
                  f"({pred.limited_by}){note}")
        return RuntimeStatus(stamp_s, pred.remaining_s, avg, temperature_k, soc, cutoff, True, STATUS_OK, reason,
                             p10, p90, spread)

    def state_voltage_sigma_v(self, calibration: Calibration | None = None) -> float:
        """Pack-voltage error of a calibrated state, V: its residual, at least a sensor's resolution.

        Without a calibration (a rested pack at a given SOC), the resolution alone.
        """
        floor = STATE_VOLTAGE_FLOOR_V_PER_CELL * (self.params.series if self.params else 1)
        if calibration is None or not math.isfinite(calibration.latest_residual_v):
            return floor
        residual = abs(calibration.latest_residual_v)
        return max(residual, floor)

    def _runtime_spread(self, pred: RuntimePrediction, load: LoadAhead, voltage_v: float) -> Spread | None:
        """The P10..P90 deviations of ``pred`` (None when it has no end within the horizon or the model fails)."""
        if not math.isfinite(pred.average_end_s):
            return None
        with self._lock:
            stamps = np.fromiter(self._load.stamps, float)
            currents = np.fromiter(self._load.currents, float)
            voltages = np.fromiter(self._load.voltages, float)
        demand = currents * voltages ** load.exponent if load.exponent > 0 else currents
        sigma = future_load_sigma(stamps, demand, pred.average_end_s)
        load = replace(load, sigma=sigma if math.isfinite(sigma) else 0.0)
        try:
            return runtime_spread(self._background_runner(), pred.calibration.start, pred.calibration.soc, pred, load,
                                  self.uncertainty, self.state_voltage_sigma_v(pred.calibration), voltage_v)
        except BatteryPredictorError:
            return None

    def _background_runner(self) -> PackModel:
        """The pack model for the runtime update: each run first waits for route answers in progress."""
        return cast(PackModel, YieldingRunner(self._runner(), self.route_priority))

    def _load_kind(self, resistance_ohm: float) -> LoadKind:
        """The load model ahead: the configured kind, or (``"auto"``) the cycle's (call under the lock)."""
        if self.config.load_model == "power":
            return LoadKind(1.0, math.nan, math.nan, 0, False)
        if self.config.load_model == "current":
            return LoadKind(0.0, math.nan, math.nan, 0, False)
        return self._load.kind(resistance_ohm, self.load_kind_prior)

    def can_accept_route(self, sections: Sequence[RouteSection], now_s: float, *, starts_away_from_charger: bool = False,
                         ends_away_from_charger: bool = False) -> RouteDecision:
        """Decide a route (sections: :class:`~battery_predictor.profiles.ranger.RouteSection`).

        Accepted only when the latest measurement, moved to the standstill current, is above the
        threshold, its lowest measured cell voltage (when the monitor had one) is above the cell's
        lower cut-off voltage, the freshly calibrated state reproduces the measurement within
        ``state_tolerance_v`` and the simulated route ends above the threshold. A runtime update
        running meanwhile pauses between its model runs until the answer is out (:mod:`.priority`).
        """
        with self.route_priority.answering():
            return self._can_accept_route(sections, now_s, starts_away_from_charger, ends_away_from_charger)

    def _can_accept_route(self, sections: Sequence[RouteSection], now_s: float, starts_away_from_charger: bool,
                          ends_away_from_charger: bool) -> RouteDecision:
        threshold = self.route_min_voltage_v
        if not math.isfinite(threshold):
            return rejected("params define no route threshold (thresholds.route_min_voltage_v)", threshold)
        status, reason, state = self._usable_state(now_s)
        if status != STATUS_OK or state is None:
            return rejected(f"state unknown: {reason}", threshold)
        cell_reason = self._measured_cell_below_cutoff()
        if cell_reason:
            return rejected(cell_reason, threshold)
        _, v, i, t_k = state
        temp = self._temperature(t_k)
        r_ohm = self._resistance(temp)
        if not math.isfinite(r_ohm):
            return rejected("model failed: no pack resistance at this temperature", threshold)
        v_standstill = standstill_voltage_v(v, i, self.standstill_current_a, r_ohm)
        if v_standstill < threshold:
            return rejected(f"measured {v:.2f} V at {i:.2f} A ({v_standstill:.2f} V at the standstill current "
                            f"{self.standstill_current_a:.2f} A) is already below the route threshold "
                            f"{threshold:.2f} V", threshold)
        try:
            cal = self.calibration(temp)
        except BatteryPredictorError as exc:
            return rejected(f"model failed while calibrating: {exc}", threshold)
        soc, soc_note = published_soc(cal.soc)
        if cal.clipped == "below_empty":
            return rejected(f"pack voltage {v:.2f} V at {i:.2f} A is below the model's empty state", threshold,
                            soc=soc)
        if cal.clipped != "above_full" and not abs(cal.latest_residual_v) <= self.state_tolerance_v:
            return rejected(f"the model cannot reproduce the measured {v:.2f} V (off by {cal.latest_residual_v:+.2f} V "
                            f"after calibration, tolerance {self.state_tolerance_v:.2f} V): state uncertain",
                            threshold, soc=soc)
        decision = evaluate_route_at_risk(self._runner(), cal.start, sections, temp, threshold_v=threshold,
                                          standstill_current_a=self.standstill_current_a, currents=self._currents,
                                          risk=self.config.decision_risk, model=self.uncertainty,
                                          state_voltage_sigma_v=self.state_voltage_sigma_v(cal))
        floor_reason = self._charge_floor_reason(decision) if decision.accepted else ""
        if floor_reason:
            decision = replace(decision, accepted=False,
                               reason=f"rejected: {floor_reason}; {decision.reason.split(': ', 1)[-1]}")
        notes = [soc_note] if soc_note else []
        if cal.soc < 0.05 and decision.accepted:
            notes.append("the SOC scale's 0 is the OCV at the params' 0 % point; the pack may be used below it "
                         "and the threshold, not the SOC, decides")
        if starts_away_from_charger:
            notes.append("starts away from the charger (state as measured now)")
        if ends_away_from_charger:
            notes.append("ends away from the charger: no return leg included")
        reason = decision.reason + ("; " + "; ".join(notes) if notes else "")
        return replace(decision, state_of_charge=soc, reason=reason)

    def _charge_floor_reason(self, decision: RouteDecision) -> str:
        """Why ``decision``'s route goes deeper than the fit data's deepest state allows ("" when it does not).

        The floor (:func:`~.safety.charge_floor`) is computed once, on the first route that asks.
        """
        deepest = DeepestState.from_thresholds(self.params.thresholds) if self.params is not None else None
        if deepest is None:
            return ""
        if self._floor is None:
            try:
                floor = charge_floor(self._runner(), deepest, threshold_v=self.route_min_voltage_v,
                                     standstill_current_a=self.standstill_current_a,
                                     resistance_ohm=self._resistance(deepest.temperature_k))
            except BatteryPredictorError as exc:
                return f"model failed on the fit data's deepest state: {exc}"
            self._floor = (floor,)
        floor = self._floor[0]
        if floor is None:
            return ""
        end_soc = decision.end_soc(self._runner().capacity_ah)
        return floor.reason(end_soc) if end_soc < floor.soc else ""


def published_soc(soc: float) -> tuple[float, str]:
    """The SOC as published (clamped to 0..1) and a note when the model's value lies outside.

    The model's SOC is PyBaMM's linear scale between the OCV at the cell's lower (0) and upper
    (1) voltage cut-off; a pack may be used beyond them (e.g. a route threshold below the 0 %
    OCV point), so the model's value is given in the note when it is clamped.
    """
    if not math.isfinite(soc):
        return math.nan, ""
    if soc < 0.0:
        return 0.0, f"model SOC {soc:.3f} (below the 0 % OCV point)"
    if soc > 1.0:
        return 1.0, f"model SOC {soc:.3f} (above the 100 % OCV point)"
    return soc, ""


def _invalid_runtime(stamp_s: float, cutoff_v: float, status: int, reason: str, *, remaining_s: float = math.nan,
                     temperature_k: float = math.nan) -> RuntimeStatus:
    return RuntimeStatus(stamp_s, remaining_s, math.nan, temperature_k, math.nan, cutoff_v, False, status, reason)


def _pick(*values: object) -> float:
    for v in values:
        if v is not None and isinstance(v, (int, float)) and math.isfinite(v):
            return float(v)
    return math.nan
