"""TPE fitting recovers a pack that liionpack made (solver-heavy; the TPE mechanics are in test/unit/test_fit.py)."""

from __future__ import annotations

import pytest

from battery_predictor.fitting.cost import r2_mod
from battery_predictor.fitting.optimiser import TPEOptimiser
from battery_predictor.fitting.problem import FitProblem, request_for_recording
from battery_predictor.fitting.space import fit_space
from battery_predictor.simulation import get_simulator


@pytest.mark.slow


@pytest.mark.slow
def test_fit_on_liionpack_data_reaches_r2_099_on_held_out_profile(temi_params, synthetic_temi):
    truth_values, _, train, held_out = synthetic_temi
    names = tuple(truth_values)
    problem = FitProblem(temi_params, [train], get_simulator("fast"), initial_state="params")
    result = TPEOptimiser(n_trials=90, seed=1, progress=False).run(problem, fit_space(temi_params, names))
    fitted = temi_params.with_values(result.best_values)
    res = get_simulator("fast").simulate(fitted, request_for_recording(fitted, held_out, initial_state="params",
                                                                       extend_s=0.2 * held_out.duration_s))
    score = r2_mod(held_out.relative_time_s, held_out.voltage_v, res.time_s, res.pack_voltage_v)
    start = get_simulator("fast").simulate(temi_params, request_for_recording(temi_params, held_out,
                                                                              initial_state="params"))
    start_score = r2_mod(held_out.relative_time_s, held_out.voltage_v, start.time_s, start.pack_voltage_v)
    assert start_score < 0.97  # the starting model is clearly wrong on this data
    assert score >= 0.99
