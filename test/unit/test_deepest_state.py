"""The fit data's deepest state: found in the recordings, kept in a fitted params file, a floor for routes."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.fitting.data_limits import with_deepest_state
from battery_predictor.params import load_params
from battery_predictor.prediction.core import PredictorConfig, PredictorCore
from battery_predictor.profiles.ranger import longest_route
from battery_predictor.recording import DEEPEST_STATE_KEYS, DeepestState, Recording, deepest_state

PARAMS = Path(__file__).resolve().parents[2] / "params"
T_K = 298.15


def stepped_recording(voltage_v, current_a, temperature_k=None) -> Recording:
    n = len(voltage_v)
    return Recording(np.arange(n, dtype=float), np.asarray(voltage_v, dtype=float), np.asarray(current_a, dtype=float),
                     temperature_k=None if temperature_k is None else np.asarray(temperature_k, dtype=float))


def test_the_deepest_state_is_the_lowest_voltage_after_the_ohmic_drop_not_the_lowest_voltage():
    # steps of 0.1 Ohm: every sample but the last is 52.0 V with the drop added back; 50.5 V at 1 A is 50.6 V
    rec = stepped_recording([52.0, 51.0, 50.0, 51.4, 50.9, 50.5, 50.5], [0.0, 10.0, 20.0, 6.0, 11.0, 15.0, 1.0])
    deepest = deepest_state([rec], T_K)
    assert deepest is not None
    assert (deepest.voltage_v, deepest.current_a) == (50.5, 1.0)
    assert deepest.temperature_k == T_K  # the recording has none: the default


def test_charging_samples_are_never_the_deepest_and_the_measured_temperature_is_kept():
    rec = stepped_recording([48.0, 47.0, 49.0], [2.0, -5.0, 2.0], temperature_k=[300.0, 301.0, 302.0])
    deepest = deepest_state([rec], T_K)
    assert (deepest.voltage_v, deepest.current_a, deepest.temperature_k) == (48.0, 2.0, 300.0)
    assert deepest_state([stepped_recording([48.0], [-1.0])], T_K) is None


def test_the_deepest_state_round_trips_through_a_fitted_params_file(tmp_path):
    params = load_params(PARAMS / "ranger_mini.yaml")
    rec = stepped_recording([50.0, 47.5, 47.2], [1.7, 2.3, 2.2])
    kept, deepest = with_deepest_state(params, [rec])
    assert deepest == DeepestState(47.2, 2.2, params.ambient_temperature_k)
    kept.to_yaml(tmp_path / "fit.yaml")
    again = load_params(tmp_path / "fit.yaml")
    assert DeepestState.from_thresholds(again.thresholds) == deepest
    assert again.thresholds["route_min_voltage_v"] == params.thresholds["route_min_voltage_v"]


def test_a_deepest_state_outside_the_packs_voltage_window_is_not_kept():
    params = load_params(PARAMS / "ranger_mini.yaml")
    kept, deepest = with_deepest_state(params, [stepped_recording([50.0, 44.0], [1.7, 2.0])])  # window 45-54 V
    assert deepest is None and not any(key in kept.thresholds for key in DEEPEST_STATE_KEYS)


def ranger_at(voltage_v: float, deepest: DeepestState | None) -> PredictorCore:
    params = load_params(PARAMS / "ranger_mini.yaml")
    if deepest is not None:
        params = replace(params, thresholds={**params.thresholds, **deepest.as_thresholds()})
    core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "ranger_mini.yaml")), params=params)
    for t in range(0, 60, 5):
        core.update_state(float(t), voltage_v, 1.7, T_K)
    return core


def test_a_route_deeper_than_fit_data_that_stopped_above_the_threshold_is_rejected_with_the_reason():
    route = longest_route(40.0).sections
    assert ranger_at(47.6, None).can_accept_route(route, 56.0).accepted  # the model alone says yes
    decision = ranger_at(47.6, DeepestState(47.6, 2.2, T_K)).can_accept_route(route, 56.0)
    assert not decision.accepted
    assert decision.reason.startswith("rejected: the route would end at model SOC")
    assert "deepest state of the fit data (47.60 V at 2.20 A" in decision.reason
    assert decision.predicted_voltage_v == pytest.approx(
        ranger_at(47.6, None).can_accept_route(route, 56.0).predicted_voltage_v)


def test_the_floor_leaves_routes_that_end_above_it_and_fit_data_that_reached_the_threshold_alone():
    route = longest_route(40.0).sections
    stopped_high = DeepestState(47.6, 2.2, T_K)
    assert ranger_at(48.5, stopped_high).can_accept_route(route, 56.0).accepted
    reached = ranger_at(47.6, DeepestState(45.5, 2.2, T_K)).can_accept_route(route, 56.0)
    alone = ranger_at(47.6, None).can_accept_route(route, 56.0)
    assert (reached.accepted, reached.reason) == (alone.accepted, alone.reason)


def test_a_floor_the_model_cannot_compute_rejects_the_route_with_the_reason(monkeypatch):
    core = ranger_at(48.5, DeepestState(47.6, 2.2, T_K))
    real = core._resistance
    monkeypatch.setattr(core, "_resistance", lambda temperature_k: math.nan if temperature_k == T_K + 0.5 else
                        real(temperature_k))
    core.params = replace(core.params, thresholds={**core.params.thresholds,
                                                   **DeepestState(47.6, 2.2, T_K + 0.5).as_thresholds()})
    decision = core.can_accept_route(longest_route(40.0).sections, 56.0)
    assert not decision.accepted
    assert "model failed on the fit data's deepest state: no pack resistance" in decision.reason
