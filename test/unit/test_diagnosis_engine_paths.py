"""The diagnosis's runs on the SPM engine agree with its PyBaMM solves, and what the engine cannot run is counted."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.diagnosis.candidates import candidate
from battery_predictor.diagnosis.engine import Engine, observe
from battery_predictor.params import load_params
from battery_predictor.recording import Recording
from battery_predictor.simulation import SimulationRequest, StepLoad
from battery_predictor.simulation.fast import FastPackSimulator

PARAMS = Path(__file__).resolve().parents[2] / "params"

#: One fitted value set per candidate the engine runs (far from the baseline, so a wrong mapping shows).
THETAS = {
    "none": {},
    "capacity_fade": {"cell_capacity_loss": 0.12, "lithium_inventory_loss": 0.08},
    "resistance_growth": {"contact_resistance_ohm": 0.02},
    "current_offset": {"current_offset_a": 0.4},
    "cell_imbalance": {"weak_group_capacity_fraction": 0.8},
    "hysteresis": {"hysteresis_half_width_v": 0.012, "hysteresis_decay_rate": 40.0, "initial_hysteresis_state": -0.3},
}


@pytest.fixture(scope="module")
def temi():
    return load_params(PARAMS / "temi.yaml")


@pytest.fixture(scope="module")
def observed(temi):
    """A 2 h Temi-like day (10 s steps) that a low start takes to the cut-off, with a constant temperature."""
    from battery_predictor.profiles.temi import generate_usage_profile

    load = StepLoad.from_profile(generate_usage_profile(seed=3, max_duration_s=2 * 3600)).scale_current(3.0)
    load = load.resample(10.0)
    res = FastPackSimulator().simulate(temi, SimulationRequest(load=load, initial_soc=0.45,
                                                               output_time_s=np.arange(0, load.end_s, 10.0)))
    rec = Recording(time_s=res.time_s, voltage_v=res.pack_voltage_v, current_a=res.pack_current_a,
                    temperature_k=np.full(res.time_s.size, 298.15))
    return observe(rec, temi)


@pytest.mark.parametrize("cause", list(THETAS))
def test_the_engine_runs_each_candidate_as_pybamm_solves_it(cause, temi, observed):
    cand = candidate(cause)
    on_engine, on_pybamm = Engine(), Engine(rtol=1e-9, atol=1e-11, spm_engine=False)
    for soc, t_end in ((0.45, None), (0.45, observed.t_split), (0.3, None)):
        a = cand.simulate(on_engine, temi, observed, THETAS[cause], soc, t_end=t_end)
        b = cand.simulate(on_pybamm, temi, observed, THETAS[cause], soc, t_end=t_end)
        assert a.reached_cutoff == b.reached_cutoff
        assert abs(a.end_time_s - b.end_time_s) <= 10.0  # one report step
        n = min(a.t.size, b.t.size)
        assert abs(a.t.size - b.t.size) <= 1
        np.testing.assert_array_equal(a.t[:n], b.t[:n])
        rms_mv = 1e3 * float(np.sqrt(np.mean((a.v_pack[:n] - b.v_pack[:n]) ** 2)))
        assert rms_mv < 0.1, rms_mv  # exact stepping against PyBaMM's IDAKLU at rtol 1e-9
        assert np.max(np.abs(a.v_cell_min[:n] - b.v_cell_min[:n])) < 5e-4
    assert on_engine.engine_runs == 3 and not on_engine.pybamm_reasons
    assert on_pybamm.engine_runs == 0 and sum(on_pybamm.pybamm_reasons.values()) == 3


def test_the_engine_is_closer_to_a_tight_pybamm_solve_than_the_diagnosis_own_pybamm_tolerances(temi, observed):
    tight = candidate("none").simulate(Engine(rtol=1e-9, atol=1e-11, spm_engine=False), temi, observed, {}, 0.45)
    loose = candidate("none").simulate(Engine(spm_engine=False), temi, observed, {}, 0.45)
    exact = candidate("none").simulate(Engine(), temi, observed, {}, 0.45)
    n = min(tight.t.size, loose.t.size, exact.t.size)

    def rms(x):
        return float(np.sqrt(np.mean((x.v_pack[:n] - tight.v_pack[:n]) ** 2)))

    assert rms(exact) < 0.1 * rms(loose)


def test_a_run_the_engine_cannot_take_is_solved_by_pybamm_and_counted_with_its_reason(temi, observed):
    cand = candidate("electrolyte_transport")
    engine = Engine()
    before = engine.usage()
    sim = cand.simulate(engine, temi, observed, {"bruggeman_exponent": 2.0}, 0.45, t_end=observed.t_split)
    assert sim.t.size > 10
    usage = engine.usage_since(before)
    assert usage["engine_runs"] == 0 and usage["pybamm_runs"] == 1
    (reason,) = usage["pybamm_reasons"]
    assert "Bruggeman" in reason or "electrolyte" in reason or "SPMe" in reason


def test_usage_since_counts_only_the_runs_after_the_mark(temi, observed):
    engine = Engine()
    candidate("none").simulate(engine, temi, observed, {}, 0.45, t_end=observed.t_split)
    before = engine.usage()
    candidate("resistance_growth").simulate(engine, temi, observed, THETAS["resistance_growth"], 0.45)
    assert engine.usage_since(before) == {"engine_runs": 1, "pybamm_runs": 0, "pybamm_reasons": {}}
