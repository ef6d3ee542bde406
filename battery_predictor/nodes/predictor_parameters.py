"""The predictor node's parameters that make its core's :class:`~battery_predictor.prediction.core.PredictorConfig`.

One entry per config field, with the description and range ``ros2 param describe`` shows; the node
declares them with :func:`~battery_predictor.nodes._params.declare_config_fields`. A default left out is
the core's own (the core's tuning is the parameter's default).
"""

from __future__ import annotations

from battery_predictor.nodes._params import FloatParameter, StrParameter
from battery_predictor.prediction.core import DRIFT_CORRECTIONS, END_EVENTS, LOAD_MODELS, PEAK_SOURCES
from battery_predictor.prediction.load_estimate import ESTIMATORS
from battery_predictor.prediction.pack_model import BACKENDS
from battery_predictor.prediction.temperature import THERMAL_FORECASTS

#: The parameters of :class:`PredictorConfig`, in the order ``ros2 param list`` shows them.
PREDICTOR_PARAMETERS: tuple[FloatParameter | StrParameter, ...] = (
    StrParameter("params_file", "Fitted pack params YAML (output of 'battery-predictor fit'): absolute, relative to "
                 "the working directory, or the name of a bundled file such as temi.yaml.", default="",
                 params_file=True),
    FloatParameter("cutoff_voltage_v", "Pack voltage at which the robot stops (remaining runtime ends), V; 0 = the "
                   "params file's thresholds.runtime_cutoff_voltage_v (else pack.min_voltage_v).", 0.0, 1000.0,
                   default=0.0, zero_means_unset=True),
    FloatParameter("route_min_voltage_v", "No route may end below this pack voltage at the standstill current, V; "
                   "0 = the params file's thresholds.route_min_voltage_v.", 0.0, 1000.0, default=0.0,
                   zero_means_unset=True),
    FloatParameter("standstill_current_a", "Current the route threshold applies at, A; 0 = the params file's "
                   "thresholds.standstill_current_a (else 1.70 A).", 0.0, 1000.0, default=0.0,
                   zero_means_unset=True),
    FloatParameter("stale_after_s", "A pack state older than this (node clock) is stale, s.", 0.01, 86400.0,
                   ),
    FloatParameter("charge_current_a", "A current below -charge_current_a charges the pack, A.", 0.0, 1000.0),
    FloatParameter("charge_session_s", "Charging held this long is a charging session and ends the present "
                   "discharge cycle (its load statistics restart), s; shorter charging (regenerative braking, "
                   "blips) stays in the cycle.", 0.0, 86400.0),
    StrParameter("load_estimator", "Average load of the present cycle: 'cycle' (mean since the cycle began, the "
                 "paper's) or 'ewma' (exponentially weighted, load_time_constant_s).", ESTIMATORS),
    StrParameter("load_model", "What of the average load stays constant ahead: 'auto' (the cycle's windows decide; "
                 "until they can, the params' operating.load_prior_power_fraction, default a constant power), "
                 "'power' (the current rises as the pack voltage falls, as behind DC-DC converters and drives) or "
                 "'current' (the paper's).", LOAD_MODELS),
    FloatParameter("load_time_constant_s", "Time constant of the 'ewma' load estimator, s.", 1.0, 86400.0),
    FloatParameter("state_tolerance_v_per_cell", "Largest model-vs-measurement voltage disagreement per series "
                   "cell before the state is recalibrated; a fresh calibration still this far off rejects routes, "
                   "V.", 0.001, 1.0),
    FloatParameter("jump_tolerance_v_per_cell", "A voltage step between two pack states beyond this per series "
                   "cell (plus twice what the current step explains) is a new pack state (battery swap): the "
                   "history before it is dropped, V.", 0.001, 5.0),
    FloatParameter("default_temperature_k", "Temperature assumed when none is measured, K; 0 = the params file's "
                   "operating.ambient_temperature_k.", 0.0, 500.0, default=0.0, zero_means_unset=True),
    FloatParameter("calibration_window_s", "History the SOC calibration simulates, s (0 = the latest pack state "
                   "only, as the paper).", 0.0, 86400.0),
    FloatParameter("recalibrate_after_s", "Full SOC calibrations at most this far apart, s; in between the "
                   "calibrated state is carried forward with the measured current.", 0.0, 86400.0),
    FloatParameter("peak_current_quantile", "Quantile of the present cycle's 5 s currents taken as its recurring "
                   "load peak: the runtime ends when such a peak pulls the pack to the cut-off (0 = under the "
                   "average load, as the paper).", 0.0, 1.0),
    StrParameter("peak_source", "Which peaks stop the robot: 'window' (5 s window means below the cut-off, as the "
                 "paper's robots) or 'sample' (a single sample below it, e.g. test equipment or a BMS cut-off).",
                 PEAK_SOURCES),
    FloatParameter("peak_duration_s", "How long a sample peak lasts in the model, s (peak_source 'sample').",
                   0.01, 60.0),
    FloatParameter("decision_risk", "Accepted probability that a route (or a task with the walk back to the "
                   "charger) ends below its threshold: accepted only when the voltage the pack stays above with "
                   "probability 1 - decision_risk is at or above it (0.1 = the P10 voltage; 0.5 = the P50, as the "
                   "paper).", 0.001, 0.5),
    StrParameter("drift_correction", "A carried state more than state_tolerance_v_per_cell off the measurement is "
                 "recalibrated onto it ('full') or just inside the tolerance, half of it left on the side it left "
                 "('smallest'; for flat-OCV cells such as LiFePO4); 'auto' takes 'smallest' where the OCVs within "
                 "the tolerance span more than 0.3 of the capacity (a flat OCV), else 'full'.", DRIFT_CORRECTIONS),
    StrParameter("end_event", "Where the runtime of a load with peaks ends: where a peak at peak_current_quantile "
                 "drawn at any moment reaches the cut-off ('peak'), or the median end of futures resampled in "
                 "10 min blocks from the cycle's own windows ('sampled'); 'auto' takes 'sampled' where the cycle's "
                 "heavy windows (at or above their 0.9 quantile) last 15 s or more on average (a robot's usage "
                 "states), else 'peak' (a drive cycle's short spikes).", END_EVENTS),
    StrParameter("thermal_forecast", "The cell temperature ahead of the runtime forecast: 'auto' integrates it "
                 "from the latest measured temperature with the params' lumped thermal cell when they carry one "
                 "(heat from the load, exchange with ambient_temperature_k), else holds it; 'held' always holds "
                 "the latest measurement.", THERMAL_FORECASTS),
    FloatParameter("ambient_temperature_k", "Ambient temperature of a self-heating forecast, K; 0 = the lowest "
                   "cell temperature measured since the present discharge cycle began.", 0.0, 400.0, default=0.0,
                   zero_means_unset=True),
    StrParameter("simulator", "Pack model: 'auto' (the SPM engine unless the params activate extensions, then "
                 "PyBaMM's solver), 'engine' or 'pybamm'.", BACKENDS),
    StrParameter("route_currents_file", "Per-(payload, slope) current samples of the luggage robot; empty = the "
                 "bundled ranger_currents.yaml.", default="", params_file=True),
)
