"""A recording that starts under load: its initial OCV is not its first voltage (issue 17, Panasonic Cycle1)."""

from __future__ import annotations

import numpy as np
import pytest

from battery_predictor.fitting.problem import loaded_start_ocv_v, request_for_recording, starts_at_rest
from battery_predictor.recording import Recording
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator


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
    assert request_for_recording(temi_params, rec, initial_state="voltage").initial_pack_ocv_v == rec.voltage_v[0]
