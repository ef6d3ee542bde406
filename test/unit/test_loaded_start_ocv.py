"""A recording that starts under load: its initial OCV is not its first voltage (issue 17, Panasonic Cycle1)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.fitting.identifiable import FULL_OCV_MARGIN_V
from battery_predictor.fitting.problem import (
    REST_AVERAGE_S,
    initial_voltage_v,
    loaded_start_ocv_v,
    request_for_recording,
    starts_at_rest,
)
from battery_predictor.params import load_params
from battery_predictor.recording import Recording
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator

REPO = Path(__file__).resolve().parents[2]


def _recording(params, load: StepLoad, ocv_v: float) -> Recording:
    sim = get_simulator("engine")
    t = np.arange(0.0, load.end_s - 1.0, 5.0)
    res = sim.simulate(params, SimulationRequest(load=load, initial_pack_ocv_v=ocv_v, output_time_s=t))
    return Recording(res.time_s, res.pack_voltage_v, load.current_at(res.time_s), source="synthetic")


def test_the_initial_ocv_of_a_recording_that_starts_under_load_is_found_from_the_model_drop(temi_params):
    truth_ocv = 15.6
    load = StepLoad.from_durations([600.0, 300.0, 600.0], [20.0, 5.0, 30.0])
    rec = _recording(temi_params, load, truth_ocv)
    assert not starts_at_rest(temi_params, rec)
    first = float(rec.voltage_v[0])
    assert truth_ocv - first > 0.03  # the drop under 20 A: the first voltage is no OCV
    ocv = loaded_start_ocv_v(temi_params, rec, get_simulator("engine"))
    assert ocv == pytest.approx(truth_ocv, abs=2e-3)


def test_a_recording_at_rest_keeps_its_first_voltage(temi_params):
    load = StepLoad.from_durations([60.0, 600.0], [0.0, 20.0])
    rec = _recording(temi_params, load, 15.6)
    assert starts_at_rest(temi_params, rec)
    assert loaded_start_ocv_v(temi_params, rec, get_simulator("engine")) == float(rec.voltage_v[0])
    assert request_for_recording(temi_params, rec, initial_state="voltage").initial_pack_ocv_v == \
        pytest.approx(rec.voltage_v[0], abs=1e-9)


def _noisy(time_s: np.ndarray, current_a: np.ndarray, seed: int = 3) -> Recording:
    """15.6 V at rest read with 5 mV noise and 10 mV steps, then lower under load."""
    rng = np.random.default_rng(seed)
    v = np.round((np.where(current_a > 0, 15.2, 15.6) + rng.normal(0.0, 0.005, time_s.size)) / 0.01) * 0.01
    return Recording(time_s, v, current_a, source="noisy")


def test_a_starting_rest_gives_its_ocv_as_the_mean_of_its_samples_not_one_quantised_reading(temi_params):
    t = np.arange(0.0, 600.0, 5.0)
    rec = _noisy(t, np.where(t < 300.0, 0.0, 10.0))
    first_minute = t <= REST_AVERAGE_S
    assert initial_voltage_v(temi_params, rec) == pytest.approx(np.mean(rec.voltage_v[first_minute]))
    assert request_for_recording(temi_params, rec, initial_state="voltage").initial_pack_ocv_v == \
        pytest.approx(np.mean(rec.voltage_v[first_minute]))


def test_a_rest_shorter_than_the_average_stops_at_the_first_sample_under_load(temi_params):
    t = np.arange(0.0, 600.0, 5.0)
    rec = _noisy(t, np.where(t < 20.0, 0.0, 10.0))
    assert initial_voltage_v(temi_params, rec) == pytest.approx(np.mean(rec.voltage_v[:4]))
    assert initial_voltage_v(temi_params, rec) > 15.5  # the loaded samples (15.2 V) are not averaged in


def test_a_start_under_load_keeps_its_first_sample(temi_params):
    t = np.arange(0.0, 600.0, 5.0)
    rec = _noisy(t, np.full(t.size, 10.0))
    assert initial_voltage_v(temi_params, rec) == rec.voltage_v[0]


class _DropsMoreNearFull:
    """A stand-in simulator whose first voltage falls as the OCV rises above 4.15 V (a model whose
    drop under load explodes near full charge, as Chen2020's OCPs on the Panasonic fit)."""

    def simulate(self, params, request):
        from battery_predictor.simulation.base import PackSimResult

        ocv = float(request.initial_pack_ocv_v)
        v = ocv - 0.05 if ocv < 4.15 else 4.10 - 2.0 * (ocv - 4.15)
        return PackSimResult(time_s=np.array([0.0]), pack_voltage_v=np.array([v]), pack_current_a=np.array([1.9]),
                             min_cell_voltage_v=np.array([v]), termination="end_of_load", end_time_s=2.0)


def test_a_model_that_cannot_reach_the_first_voltage_stops_at_the_highest_plausible_ocv():
    panasonic_params = load_params(REPO / "params" / "panasonic_18650pf.yaml")
    rec = Recording(np.array([0.0, 1.0, 2.0]), np.array([4.157, 4.05, 4.06]), np.array([1.87, 1.82, 1.39]),
                    source="cycle1")
    with pytest.warns(UserWarning, match="stays .* below the measured 4.157 V even from an OCV of 4.250 V"):
        ocv = loaded_start_ocv_v(panasonic_params, rec, _DropsMoreNearFull())
    assert ocv == pytest.approx(4.20 + FULL_OCV_MARGIN_V)
