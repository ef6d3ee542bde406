"""The temperature ahead of a runtime forecast: self-heating with a lumped thermal cell, or held (no ROS)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.prediction.calibration import Calibration
from battery_predictor.prediction.core import STATUS_OK, PredictorConfig, PredictorCore
from battery_predictor.prediction.pack_model import pack_model
from battery_predictor.prediction.runtime import predict_remaining_runtime
from battery_predictor.prediction.temperature import AmbientEstimate, temperature_ahead
from battery_predictor.profiles.ranger import RouteSection
from battery_predictor.simulation.engine.segments import EngineState
from battery_predictor.simulation.extensions import EA_SERIES

PARAMS = Path(__file__).resolve().parents[2] / "params"
COLD_K = 273.15


@pytest.fixture(scope="module")
def cold_cell():
    """The LG M50 (Chen2020) whose series resistance triples from 25 to 0 degC: warming lengthens the runtime."""
    params = load_params(PARAMS / "lgm50.yaml")
    return replace(params, extensions=["temperature"], extra={**params.extra, EA_SERIES: 30000.0})


@pytest.fixture(scope="module")
def thermal_pack(cold_cell):
    pack, line = pack_model(replace(cold_cell, options={"thermal": "lumped"}))
    assert line.startswith("engine") and pack.thermal
    return pack


@pytest.fixture(scope="module")
def isothermal_pack(cold_cell):
    pack, _ = pack_model(cold_cell)
    assert not pack.thermal
    return pack


def _forecast(pack, ahead, soc=0.9, current_a=10.0):
    cal = Calibration(soc, 0.0, "", ahead.start(pack, soc), 0.0)
    return predict_remaining_runtime(pack, 3.6, current_a, ahead.run_temperature_k, current_a, 2.5, calibration=cal,
                                     average_power_w=None)


def test_a_self_heating_forecast_warms_and_runs_longer_than_a_held_temperature(thermal_pack, isothermal_pack):
    heating = temperature_ahead(thermal_pack, COLD_K, COLD_K)
    held = temperature_ahead(isothermal_pack, COLD_K, COLD_K)
    assert heating.self_heating and not held.self_heating and "no lumped thermal cell" in held.note
    warm, cold = _forecast(thermal_pack, heating), _forecast(isothermal_pack, held)
    assert cold.limited_by == warm.limited_by == "pack_cutoff"
    assert warm.end_temperature_k > COLD_K + 5.0  # 2C from 0 degC: the cell heats itself
    assert math.isnan(cold.end_temperature_k)
    assert warm.remaining_s > 1.01 * cold.remaining_s  # 2 % here: the end is on the knee of the OCV
    # the thermal cell held at the cold temperature (a cell that cannot heat) agrees with the isothermal one:
    # what lengthens the runtime is the warming, not a different cell
    no_load = thermal_pack.run(heating.start(thermal_pack, 0.9), [(600.0, 0.0)], COLD_K)
    assert float(no_load.final_state.cell_temperature_k[0]) == pytest.approx(COLD_K, abs=1e-6)


def test_with_zero_load_a_warm_cell_relaxes_to_the_ambient(thermal_pack):
    ambient_k, warm_k = 288.15, 318.15
    start = thermal_pack.at_cell_temperature(0.6, warm_k)
    temps = [float(thermal_pack.run(start, [(hours * 3600.0, 0.0)], ambient_k).final_state.cell_temperature_k[0])
             for hours in (0.25, 1.0, 6.0)]
    assert warm_k > temps[0] > temps[1] > temps[2] >= ambient_k - 1e-6  # monotone, never below the ambient
    assert temps[2] == pytest.approx(ambient_k, abs=0.05)
    cold = thermal_pack.run(thermal_pack.at_cell_temperature(0.6, 268.15), [(6 * 3600.0, 0.0)], ambient_k)
    assert float(cold.final_state.cell_temperature_k[0]) == pytest.approx(ambient_k, abs=0.05)  # and from below


def test_a_start_at_the_ambient_equals_the_run_from_the_soc(thermal_pack):
    segments = [(300.0, 8.0), (120.0, 1.0), (600.0, 5.0)]
    plain = thermal_pack.run(0.7, segments, 290.0)
    moved = thermal_pack.run(thermal_pack.at_cell_temperature(0.7, 290.0), segments, 290.0)
    np.testing.assert_allclose(moved.pack_voltage_v, plain.pack_voltage_v, atol=1e-9)
    assert thermal_pack.soc_of(moved.final_state) == pytest.approx(thermal_pack.soc_of(plain.final_state))
    carried = thermal_pack.at_cell_temperature(plain.final_state, 300.0)
    assert isinstance(carried, EngineState) and np.all(carried.cell_temperature_k == 300.0)
    assert carried.particles is plain.final_state.particles


@pytest.mark.parametrize("cell_k, ambient_k, why", [
    (math.nan, 280.0, "not usable"),
    (500.0, 280.0, "not usable"),
])
def test_an_unusable_cell_temperature_holds_it_with_a_reason(thermal_pack, cell_k, ambient_k, why):
    ahead = temperature_ahead(thermal_pack, cell_k, ambient_k)
    assert not ahead.self_heating and why in ahead.note
    assert ahead.start(thermal_pack, 0.5) == 0.5


def test_a_thermal_cell_on_pybamm_stepping_says_how_it_runs(cold_cell):
    stepping = SimpleNamespace(params=replace(cold_cell, options={"thermal": "lumped"}))  # no at_cell_temperature
    ahead = temperature_ahead(stepping, 290.0, 280.0)
    assert not ahead.self_heating and ahead.run_temperature_k == 290.0 and "PyBaMM stepping" in ahead.note
    assert "no lumped thermal cell" in temperature_ahead(SimpleNamespace(params=cold_cell), 290.0, 280.0).note


@pytest.mark.parametrize("ambient_k", [math.nan, -1.0, 1e6])
def test_an_unknown_ambient_is_the_cells_own_temperature_stated(thermal_pack, ambient_k):
    ahead = temperature_ahead(thermal_pack, 290.0, ambient_k)
    assert ahead.self_heating and ahead.run_temperature_k == 290.0 and "ambient unknown" in ahead.note


def test_held_is_held_and_an_unknown_mode_is_refused(thermal_pack):
    ahead = temperature_ahead(thermal_pack, 290.0, 280.0, "held")
    assert not ahead.self_heating and ahead.run_temperature_k == 290.0 and "held" in ahead.note
    with pytest.raises(ValueError, match="thermal_forecast"):
        temperature_ahead(thermal_pack, 290.0, 280.0, "guess")
    with pytest.raises(ValueError, match="thermal_forecast"):
        PredictorCore(PredictorConfig(params_file=str(PARAMS / "lgm50.yaml"), thermal_forecast="guess"))


def test_the_ambient_estimate_is_the_lowest_plausible_temperature_since_its_reset():
    est = AmbientEstimate()
    assert math.isnan(est.value_k)
    for t_k in (290.0, math.nan, 285.0, 150.0, 300.0, 1e4):
        est.add(t_k)
    assert est.value_k == 285.0
    est.reset()
    assert math.isnan(est.value_k)


@pytest.fixture(scope="module")
def cold_discharge(thermal_pack):
    """A 0 degC cell's first 5 min at 10 A and its true remaining time (s), made by the thermal cell itself."""
    state = thermal_pack.at_cell_temperature(0.95, COLD_K)
    samples = []
    for k in range(60):
        run = thermal_pack.run(state, [(5.0, 10.0)], COLD_K)
        state = run.final_state
        samples.append((5.0 * (k + 1), float(run.pack_voltage_v[-1]), 10.0, float(state.cell_temperature_k[0])))
    rest = thermal_pack.run(state, [(3 * 3600.0, 10.0)], COLD_K)
    assert rest.reached_cutoff
    return samples, float(rest.end_time_s)


def _fed_core(params, samples, **config) -> PredictorCore:
    core = PredictorCore(PredictorConfig(params_file="unused.yaml", load_model="current", peak_current_quantile=0.0,
                                         **config), params=params)
    for stamp, v, i, t_k in samples:
        core.update_state(stamp, v, i, t_k)
    return core


def test_the_core_forecasts_self_heating_with_a_thermal_cell_and_says_so(cold_cell, cold_discharge):
    samples, true_s = cold_discharge
    thermal = replace(cold_cell, options={"thermal": "lumped"})
    heating = _fed_core(thermal, samples).remaining_runtime(300.0)
    held = _fed_core(thermal, samples, thermal_forecast="held").remaining_runtime(300.0)
    assert heating.status == held.status == STATUS_OK
    assert f"self-heating, ambient {samples[0][3] - COLD_K:.1f} degC" in heating.reason  # the lowest measured
    assert "degC at the end" in heating.reason
    assert "self-heating" not in held.reason
    assert heating.assumed_temperature_k == held.assumed_temperature_k == pytest.approx(samples[-1][3])
    # the cell that made the data warms: holding its present temperature ends early, the self-heating forecast
    # (the same cell) finds the true end
    assert held.remaining_s < heating.remaining_s
    assert abs(heating.remaining_s - true_s) < 0.02 * true_s < abs(held.remaining_s - true_s)
    stated = _fed_core(thermal, samples, ambient_temperature_k=COLD_K + 20.0).remaining_runtime(300.0)
    assert "ambient 20.0 degC (stated)" in stated.reason  # a stated ambient is the runs' (a wrong one misleads)
    assert abs(stated.remaining_s - true_s) > abs(heating.remaining_s - true_s)


def test_the_core_without_a_thermal_cell_or_a_temperature_holds_it(cold_cell, cold_discharge):
    samples, _ = cold_discharge
    plain = _fed_core(cold_cell, samples).remaining_runtime(300.0)
    assert plain.status == STATUS_OK and "self-heating" not in plain.reason
    thermal = replace(cold_cell, options={"thermal": "lumped"})
    core = PredictorCore(PredictorConfig(params_file="unused.yaml", load_model="current", peak_current_quantile=0.0),
                         params=thermal)
    for stamp, v, i, _ in samples:  # no temperature measured: the params' ambient, as before, and never a crash
        core.update_state(stamp, v, i, math.nan)
    rt = core.remaining_runtime(300.0)
    assert rt.status == STATUS_OK and "ambient unknown" in rt.reason
    assert rt.assumed_temperature_k == pytest.approx(thermal.ambient_temperature_k)


def test_a_charging_session_restarts_the_ambient_estimate(cold_cell, cold_discharge):
    samples, _ = cold_discharge
    core = _fed_core(replace(cold_cell, options={"thermal": "lumped"}), samples)
    assert core.temperature_ahead(samples[-1][3]).ambient_k == pytest.approx(samples[0][3])
    for k in range(70):  # 350 s of charging at 5 degC: a session
        core.update_state(305.0 + 5.0 * k, 4.0, -5.0, COLD_K + 5.0)
    assert core.temperature_ahead(COLD_K + 5.0).ambient_k == pytest.approx(COLD_K + 5.0)


def test_routes_keep_their_own_state_whatever_the_forecast_did(cold_cell, cold_discharge):
    """A self-heating forecast never makes a route warmer (more permissive): routes do not see its state."""
    samples, _ = cold_discharge
    thermal = replace(cold_cell, options={"thermal": "lumped"})
    route = [RouteSection("a", 300.0, "flat", 0.0), RouteSection("b", 75.0, "uphill", 80.0)]
    config = dict(route_min_voltage_v=3.0, standstill_current_a=1.0)
    forecasting, routing = _fed_core(thermal, samples, **config), _fed_core(thermal, samples, **config)
    for core in (forecasting, routing):
        core.precalibrate()
    assert forecasting.remaining_runtime(300.0).status == STATUS_OK
    after_forecast, alone = forecasting.can_accept_route(route, 300.0), routing.can_accept_route(route, 300.0)
    assert math.isfinite(alone.predicted_voltage_v)
    assert after_forecast.predicted_voltage_v == alone.predicted_voltage_v
    assert after_forecast.accepted == alone.accepted and after_forecast.state_of_charge == alone.state_of_charge
    # and the route's state is the one at the measured temperature (as before), not the forecast's thermal one
    route_cal = forecasting.calibration(samples[-1][3])
    heating_cal = forecasting.calibration(samples[-1][3], forecasting.temperature_ahead(samples[-1][3]))
    assert route_cal is not heating_cal and abs(route_cal.soc - heating_cal.soc) > 1e-4
    assert 0.0 < route_cal.soc < 1.0 and alone.state_of_charge == pytest.approx(route_cal.soc, abs=1e-12)
