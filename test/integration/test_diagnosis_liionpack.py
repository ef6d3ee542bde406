"""The diagnosis's weak series group (a second PyBaMM solve) against liionpack's per-cell values (solver-heavy)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from battery_predictor.diagnosis.engine import Engine, Post, observe
from battery_predictor.recording import Recording
from battery_predictor.simulation import SimulationRequest, StepLoad
from battery_predictor.simulation import extensions as ext
from battery_predictor.simulation.fast import FastPackSimulator


def test_weak_group_two_cell_model_matches_liionpack_per_cell_values(temi_params):
    from battery_predictor.profiles.temi import generate_usage_profile
    from battery_predictor.simulation.liionpack_sim import LiionpackSimulator

    temi = temi_params
    load = StepLoad.from_profile(generate_usage_profile(seed=2, max_duration_s=3600.0)).scale_current(3.0).resample(10.0)
    params = replace(temi, extensions=("cell_imbalance",), extra={ext.WEAK_FRACTION: 0.8})
    assert ext.imbalance_cell_inputs(params)["Electrode height [m]"][:: temi.series] == pytest.approx(
        0.8 * temi.value("Electrode height [m]"))
    req = SimulationRequest(load=load, initial_soc=0.35, output_time_s=np.arange(0, load.end_s, 10.0))
    lp_run = LiionpackSimulator(period_s=10.0).simulate(params, req)
    fast_run = FastPackSimulator().simulate(params, req)
    eng = Engine()
    obs = observe(Recording(time_s=lp_run.time_s, voltage_v=lp_run.pack_voltage_v, current_a=lp_run.pack_current_a,
                            temperature_k=np.full(lp_run.time_s.size, 298.15)), temi)
    sim = eng.simulate(temi, obs, concentrations=eng.concentrations_for_soc(temi, 0.35), ambient_k=298.15,
                       post=Post(weak_fraction=0.8))
    n = min(sim.t.size, lp_run.time_s.size, fast_run.time_s.size) - 1
    assert np.sqrt(np.mean((sim.v_pack[:n] - lp_run.pack_voltage_v[:n]) ** 2)) < 0.01
    assert np.max(np.abs(sim.v_pack[:n] - fast_run.pack_voltage_v[:n])) < 0.003
    plain = FastPackSimulator().simulate(temi, req)
    assert fast_run.end_time_s < plain.end_time_s  # the weak group ends the discharge earlier
