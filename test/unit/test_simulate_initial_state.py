"""`simulate --initial-state auto` on a fit's params: its data files from their fitted state, others from their own."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from battery_predictor.cli.cmd_simulate import _fitted_initial_ocvs_v, _score
from battery_predictor.recording import Recording
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator


def _recording(params, ocv_v: float, name: str) -> Recording:
    load = StepLoad.from_durations([60.0, 900.0], [0.0, 10.0])
    t = np.arange(0.0, load.end_s - 1.0, 5.0)
    res = get_simulator("engine").simulate(params, SimulationRequest(load=load, initial_pack_ocv_v=ocv_v,
                                                                     output_time_s=t))
    return Recording(res.time_s, res.pack_voltage_v, load.current_at(res.time_s), source=f"/data/{name}")


def test_a_fit_s_data_file_starts_from_its_fitted_state_and_another_from_its_own_voltage(temi_params):
    fitted = replace(temi_params, provenance={"initial_ocv_v_per_file": {"day1.csv": 3.95}})
    seen, unseen = _recording(temi_params, 15.4, "day1.csv"), _recording(temi_params, 15.9, "day2.csv")
    rows, _ = _score(fitted, [seen, unseen], get_simulator("engine"), "auto")
    assert rows[0]["initial_ocv_v"] == pytest.approx(3.95 * temi_params.series)
    assert rows[1]["initial_ocv_v"] == pytest.approx(15.9, abs=2e-3)
    assert rows[1]["r2_mod"] > 0.999  # its own state: the recording is the model's
    assert rows[1]["discharge_end_s_measured"] == pytest.approx(unseen.relative_time_s[-1])


def test_params_no_fit_wrote_keep_the_params_initial_state(temi_params):
    assert _fitted_initial_ocvs_v(temi_params) == {}
    # temi.yaml fits its initial concentrations (the paper's way): auto keeps them
    rows, _ = _score(temi_params, [_recording(temi_params, 15.9, "day2.csv")], get_simulator("engine"), "auto")
    assert rows[0]["initial_ocv_v"] is None
