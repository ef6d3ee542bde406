"""Uncertainty of the predictor's answers (no ROS): load spread, calibration of the structural part, intervals, risk."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.prediction.core import STATUS_OK, PredictorConfig, PredictorCore
from battery_predictor.prediction.uncertainty import (
    DEFAULT_CAPACITY_REL_SIGMA,
    DEFAULT_CELL_VOLTAGE_SIGMA_V,
    DEFAULT_RUNTIME_LOG_SIGMA,
    LOAD_BLOCK_S,
    Z_P90,
    RouteSpread,
    Spread,
    arrhenius_equivalent_temperature_k,
    calibrated_model_sigma,
    charge_deviation_log,
    correlation_time_s,
    future_load_sigma,
    interval,
    route_charge_sigma_ah,
    state_deviation_log,
    uncertainty_model,
)
from battery_predictor.profiles.ranger import RouteSection, longest_route

PARAMS = Path(__file__).resolve().parents[2] / "params"


def test_a_steady_load_has_no_spread_and_a_varying_one_shrinks_with_the_horizon():
    t = np.arange(0.0, 7200.0, 5.0)
    assert future_load_sigma(t, np.full(t.size, 2.0), 3600.0) == 0.0
    rng = np.random.default_rng(0)
    blocks = rng.uniform(1.0, 3.0, size=int(t[-1] // LOAD_BLOCK_S) + 1)
    demand = blocks[(t // LOAD_BLOCK_S).astype(int)]
    short, long = future_load_sigma(t, demand, 600.0), future_load_sigma(t, demand, 6 * 3600.0)
    assert 0 < long < short
    # a future mean over one block is as uncertain as one block mean (plus the present mean's own error)
    spread = np.std(blocks[:-1], ddof=1) / np.mean(demand)
    assert future_load_sigma(t, demand, LOAD_BLOCK_S) == pytest.approx(spread * math.sqrt(1 + 1 / 23), rel=0.15)


def test_few_blocks_estimate_the_block_spread_from_the_windows_correlation_time():
    t = np.arange(0.0, 600.0, 5.0)
    alternating = np.where(np.arange(t.size) % 2 == 0, 1.0, 3.0)  # decorrelates at once: blocks average it out
    persistent = np.where(t < 300.0, 1.0, 3.0)  # one level per 5 min: a block is as uncertain as a window
    assert correlation_time_s(t, alternating) == pytest.approx(5.0, abs=1e-6)
    assert correlation_time_s(t, persistent) > 0.5 * LOAD_BLOCK_S  # finite-sample estimate of a 5-min level
    assert future_load_sigma(t, alternating, 3600.0) == pytest.approx(0.5 * math.sqrt(5.0 / 300.0), rel=0.05)
    assert 0.35 < future_load_sigma(t, persistent, 3600.0) <= 0.5


def test_no_load_data_gives_nan():
    assert math.isnan(future_load_sigma([0.0], [1.0], 100.0))
    assert math.isnan(future_load_sigma(np.arange(10.0), np.zeros(10), 100.0))


def test_calibrated_model_sigma_recovers_the_spread_of_log_errors():
    rng = np.random.default_rng(1)
    p50 = rng.uniform(600.0, 6000.0, 4000)
    truth = p50 * np.exp(rng.normal(0.0, 0.2, p50.size))

    def spreads(other: float) -> list[Spread]:
        return [Spread({"load": other}, {"load": other})] * p50.size

    assert calibrated_model_sigma(p50, truth, spreads(0.0)) == pytest.approx(0.2, rel=0.05)
    # deviations that already cover everything leave nothing to the structure
    assert calibrated_model_sigma(p50, truth, spreads(1.0)) == 0.0
    # other parts of the band leave less to it
    assert calibrated_model_sigma(p50, truth, spreads(0.15)) < 0.2


def test_interval_and_charge_deviation_bracket_the_median():
    p10, p90 = interval(100.0, 0.2, 0.3)
    assert p10 == pytest.approx(100 * math.exp(-0.2)) and p90 == pytest.approx(100 * math.exp(0.3))
    lower, upper = charge_deviation_log(0.5, 2.0)
    assert lower == pytest.approx(-math.log(0.75)) and upper == pytest.approx(math.log(1.25))
    spread = Spread({"a": 0.3, "model": 0.4}, {"a": 0.1, "load_kind": 0.2})
    assert spread.total() == (pytest.approx(0.5), pytest.approx(0.3))  # an alternative model adds, spreads combine
    assert spread.with_model_sigma(0.0).total() == (pytest.approx(0.3), pytest.approx(0.3))


def test_the_state_spread_never_puts_more_charge_in_the_cell_than_the_top_of_its_range():
    # a flat OCV turns a voltage residual into a huge SOC spread; the longer side stops at the model's top
    lower, upper = state_deviation_log(0.9, 0.5, 1.05, 2.6, 1.0)
    assert upper == pytest.approx(math.log1p(0.55 * 2.6 / 1.0))
    assert lower == charge_deviation_log(0.9 * 2.6, 1.0)[0]
    assert state_deviation_log(0.1, 0.5, 1.05, 2.6, 1.0) == charge_deviation_log(0.26, 1.0)  # inside: unchanged
    assert state_deviation_log(0.1, 1.2, 1.05, 2.6, 1.0)[1] == 0.0  # at or above the top: no longer side


def test_activation_energy_scenario_is_a_temperature_further_from_the_reference():
    assert arrhenius_equivalent_temperature_k(273.15, 298.15, 1.0) == pytest.approx(273.15)
    assert arrhenius_equivalent_temperature_k(298.15, 298.15, 1.5) == pytest.approx(298.15)
    assert arrhenius_equivalent_temperature_k(273.15, 298.15, 1.3) < 273.15
    assert arrhenius_equivalent_temperature_k(318.15, 298.15, 1.3) > 318.15


def test_uncertainty_model_reads_the_fit_record_and_falls_back_to_stated_defaults():
    bare = uncertainty_model({}, 4, 298.15)
    assert bare.runtime_log_sigma == DEFAULT_RUNTIME_LOG_SIGMA
    assert bare.voltage_sigma_v == pytest.approx(4 * DEFAULT_CELL_VOLTAGE_SIGMA_V)
    assert bare.capacity_rel_sigma == DEFAULT_CAPACITY_REL_SIGMA and "uncalibrated" in bare.source
    fitted = uncertainty_model({
        "uncertainty": {"runtime_log_sigma": 0.05, "checkpoints": 18},
        "rmse_mv_per_file": [30.0, 40.0],
        "identifiability": {"parameters": [
            {"name": "negative_capacity_ah", "value": 3.0, "ci95": [2.94, 3.06]},
            {"name": "series_resistance_ohm", "value": 0.01, "ci95": [-math.inf, math.inf]}]},
    }, 1, 298.15)
    assert fitted.runtime_log_sigma == 0.05 and "calibrated on 18" in fitted.source
    assert fitted.voltage_sigma_v == pytest.approx(math.sqrt((30 ** 2 + 40 ** 2) / 2) / 1000)
    assert fitted.capacity_rel_sigma == pytest.approx(0.12 / 3.92 / 3.0)


def test_route_charge_spread_grows_with_the_route_and_averages_over_curve_points():
    one = route_charge_sigma_ah([RouteSection("a", 100.0, "uphill", 80.0)])
    four = route_charge_sigma_ah([RouteSection("a", 100.0, "uphill", 80.0)] * 4)
    long = route_charge_sigma_ah([RouteSection("a", 400.0, "uphill", 80.0)])
    assert 0 < one < four == pytest.approx(2 * one)
    assert long == pytest.approx(four, rel=0.05)  # one long section of 4x the points: the same as four short ones
    assert route_charge_sigma_ah([RouteSection("stand", 0.0, "flat", 0.0, standstill_s=60.0)]) == 0.0


def test_route_spread_probability_and_voltage_at_risk():
    spread = RouteSpread(0.5, {"model": 0.5})
    assert spread.probability_above(0.0) == pytest.approx(0.5)
    assert spread.probability_above(Z_P90 * 0.5) == pytest.approx(0.9)
    assert spread.voltage_at_risk_v(48.0, 0.1) == pytest.approx(48.0 - Z_P90 * 0.5)
    assert RouteSpread(0.0, {}).probability_above(0.1) == 1.0


def fed(params, voltage_v: float, risk: float = 0.1) -> PredictorCore:
    core = PredictorCore(PredictorConfig(params_file=str(params.source), decision_risk=risk), params=params)
    for k in range(40):
        core.update_state(1000.0 + 5 * k, voltage_v, 3.0, 298.15)
    return core


def test_a_route_with_a_thin_margin_is_accepted_on_its_median_but_rejected_at_the_default_risk(ranger_params):
    sections = longest_route(80).sections
    core = fed(ranger_params, 49.8)
    median = core.can_accept_route(sections, 1200.0)
    threshold = median.predicted_voltage_v - 0.2  # a margin well inside the spread
    thin = PredictorCore(PredictorConfig(params_file=str(ranger_params.source), route_min_voltage_v=threshold),
                         params=ranger_params)
    paper = PredictorCore(PredictorConfig(params_file=str(ranger_params.source), route_min_voltage_v=threshold,
                                          decision_risk=0.5), params=ranger_params)
    for c in (thin, paper):
        for k in range(40):
            c.update_state(1000.0 + 5 * k, 49.8, 3.0, 298.15)
    risky, p50 = thin.can_accept_route(sections, 1200.0), paper.can_accept_route(sections, 1200.0)
    assert risky.margin_v == pytest.approx(0.2, abs=0.01) and not risky.accepted
    assert 0.5 < risky.probability_above_threshold < 0.9 and risky.voltage_at_risk_v < threshold
    assert "probability above the threshold" in risky.reason and risky.reason.startswith("rejected")
    assert p50.accepted and p50.risk == 0.5
    assert median.accepted and median.probability_above_threshold > 0.99 and median.risk == 0.1


def test_decision_risk_outside_its_range_is_refused(ranger_params):
    for risk in (0.0, 0.7, math.nan):
        with pytest.raises(ValueError, match="decision_risk"):
            PredictorCore(PredictorConfig(params_file=str(ranger_params.source), decision_risk=risk), params=ranger_params)


def test_runtime_carries_an_interval_around_its_median():
    params = load_params(PARAMS / "temi.yaml")
    core = PredictorCore(PredictorConfig(params_file=str(params.source)), params=params)
    rng = np.random.default_rng(3)
    block_currents = 2.0 + 2.0 * rng.random(12)  # an hour of 5 s windows drawing 2..4 A in 5-min blocks
    for k in range(720):
        core.update_state(5.0 * k, 15.6 - 0.0004 * k, block_currents[k // 60], 298.15)
    answer = core.remaining_runtime(5.0 * 719)
    assert answer.status == STATUS_OK
    assert answer.remaining_p10_s < answer.remaining_s < answer.remaining_p90_s
    assert {"load", "state", "parameters", "model"} <= set(answer.spread.lower)
    assert answer.spread.lower["load"] > 0 and "P10..P90" in answer.reason
