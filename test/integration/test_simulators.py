"""Pack simulators: the fast path and the engine agree with liionpack on the robots' dynamic profiles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import SimulationError
from battery_predictor.params import load_params
from battery_predictor.profiles.ranger import longest_route, route_profile
from battery_predictor.profiles.temi import generate_usage_profile
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator
from battery_predictor.simulation.base import PackSimResult
from battery_predictor.simulation.fast import FastPackSimulator

PARAMS = Path(__file__).resolve().parents[2] / "params"


#: liionpack's answer per case, simulated once for the fast-path and the engine test of the case (the slow half).
_LIIONPACK: dict[str, PackSimResult] = {}


def _compare(case: str, simulator: str = "fast"):
    """``simulator`` and liionpack on the case's 10 s-resampled load (liionpack steps at 10 s)."""
    params, load, req_kwargs = _CASES[case]()
    stepped = load.resample(10.0)
    req = SimulationRequest(load=stepped, **req_kwargs)
    fast = get_simulator(simulator).simulate(params, req)
    if case not in _LIIONPACK:
        _LIIONPACK[case] = get_simulator("liionpack").simulate(params, req)
    ref = _LIIONPACK[case]
    n = min(len(fast.time_s), len(ref.time_s))
    # the final sample sits on the cut-off knee, where one step of timing dominates the difference
    diff = fast.pack_voltage_v[: n - 1] - ref.pack_voltage_v[: n - 1]
    return fast, ref, float(np.sqrt(np.mean(diff**2)))


def _temi_usage_case():
    """The shipped Temi pack from 12 % SOC under a 4 h usage profile (seed 3): down to the cut-off."""
    params = load_params(PARAMS / "temi.yaml")
    profile = generate_usage_profile(seed=3, max_duration_s=4 * 3600)
    return params, StepLoad.from_profile(profile), {"initial_soc": 0.12}


def _ranger_route_case():
    """The shipped Ranger pack from 50 % SOC over the longest route at 60 kg twice (seed 4): to the end of the load."""
    params = load_params(PARAMS / "ranger_mini.yaml")
    profile = route_profile(longest_route(60.0), seed=4)
    return params, StepLoad.from_profile(profile.concatenate(profile)), {"initial_soc": 0.5}


_CASES = {"temi_usage": _temi_usage_case, "ranger_route": _ranger_route_case}


@pytest.mark.slow
def test_fast_path_matches_liionpack_on_temi_usage_profile_to_cutoff():
    fast, ref, rms_v = _compare("temi_usage")
    assert ref.termination == "cell_cutoff" and fast.termination == "cell_cutoff"
    assert rms_v <= 0.005
    assert abs(fast.end_time_s - ref.end_time_s) / ref.end_time_s <= 0.005


@pytest.mark.slow
def test_fast_path_matches_liionpack_on_ranger_longest_route():
    fast, ref, rms_v = _compare("ranger_route")
    assert rms_v <= 0.005
    assert fast.termination == ref.termination == "end_of_load"


@pytest.mark.slow
def test_engine_matches_liionpack_on_temi_usage_profile_to_cutoff():
    """Issue 18: the engine within 5 mV RMS and 0.5 % of the time to cut-off of liionpack (identical cells)."""
    engine, ref, rms_v = _compare("temi_usage", "engine")
    assert "engine_fallback" not in engine.extra
    assert ref.termination == "cell_cutoff" and engine.termination == "cell_cutoff"
    assert rms_v <= 0.005
    assert abs(engine.end_time_s - ref.end_time_s) / ref.end_time_s <= 0.005


@pytest.mark.slow
def test_engine_matches_liionpack_on_ranger_longest_route():
    engine, ref, rms_v = _compare("ranger_route", "engine")
    assert "engine_fallback" not in engine.extra
    assert rms_v <= 0.005
    assert engine.termination == ref.termination == "end_of_load"


def test_fast_simulator_reuses_built_model_when_only_input_parameters_change():
    params = load_params(PARAMS / "temi.yaml")
    sim = FastPackSimulator()
    req = SimulationRequest(load=StepLoad.constant(7.0, 3600.0))
    a = sim.simulate(params, req)
    b = sim.simulate(params.with_values({"Electrode height [m]": 0.8}), req)
    assert sim.builds == 1
    assert b.pack_voltage_v[-1] < a.pack_voltage_v[-1]  # less electrode area -> deeper discharge
    sim.simulate(params.with_values({"Negative particle radius [m]": 6.0e-6}), req)
    assert sim.builds == 2  # particle radius shapes the mesh: rebuilt


def test_thickness_folded_into_volume_fraction_equals_a_rebuilt_model():
    params = load_params(PARAMS / "temi.yaml")
    req = SimulationRequest(load=StepLoad.from_durations([600.0, 300.0, 900.0] * 4, [3.0, 9.0, 1.5] * 4))
    mapped, rebuilt = FastPackSimulator(), FastPackSimulator(map_thickness=False)
    mapped.simulate(params, req)
    for change in ({"Negative electrode thickness [m]": 1.0e-4},
                   {"Positive electrode thickness [m]": 1.3e-4, "Negative electrode thickness [m]": 1.4e-4}):
        p = params.with_values(change)
        a, b = mapped.simulate(p, req), rebuilt.simulate(p, req)
        np.testing.assert_allclose(a.pack_voltage_v, b.pack_voltage_v, atol=2e-4)
    assert mapped.builds == 1 and rebuilt.builds == 2


def test_initial_soc_and_initial_voltage_set_the_start():
    params = load_params(PARAMS / "temi.yaml")
    sim = get_simulator("fast")
    load = StepLoad.constant(0.01, 60.0)
    full = sim.simulate(params, SimulationRequest(load=load, initial_soc=1.0))
    empty = sim.simulate(params, SimulationRequest(load=load, initial_soc=0.05))
    assert full.pack_voltage_v[0] > empty.pack_voltage_v[0] + 1.0
    by_v = sim.simulate(params, SimulationRequest(load=load, initial_pack_ocv_v=15.2))
    assert by_v.pack_voltage_v[0] == pytest.approx(15.2, abs=0.02)


def test_cutoff_terminates_and_reports_runtime():
    params = load_params(PARAMS / "temi.yaml")
    res = get_simulator("fast").simulate(params, SimulationRequest(load=StepLoad.constant(14.7, 4 * 3600.0)))
    assert res.termination == "cell_cutoff"
    assert 0.5 * 3600 < res.end_time_s < 1.5 * 3600  # ~1C on a 14.7 Ah pack
    assert res.time_to_pack_voltage_s(13.3) < res.end_time_s


def test_infeasible_parameters_raise_simulation_error():
    params = load_params(PARAMS / "temi.yaml")
    bad = params.with_values({"Initial concentration in negative electrode [mol.m-3]": 1e6})
    with pytest.raises(SimulationError):
        get_simulator("fast").simulate(bad, SimulationRequest(load=StepLoad.constant(3.0, 600.0)))
    with pytest.raises(SimulationError, match="initial SOC"):
        get_simulator("fast").simulate(params, SimulationRequest(load=StepLoad.constant(3.0, 60.0), initial_soc=1.5))


def test_fast_simulator_refuses_per_cell_values():
    params = load_params(PARAMS / "temi.yaml")
    req = SimulationRequest(load=StepLoad.constant(3.0, 60.0),
                            cell_inputs={"Electrode height [m]": np.full(24, 0.9)})
    with pytest.raises(SimulationError, match="liionpack"):
        get_simulator("fast").simulate(params, req)


def test_step_load_resample_conserves_charge():
    load = StepLoad.from_durations([3.0, 7.5, 19.0, 1.0], [1.0, 4.0, 2.0, 0.5])
    for period in (1.0, 2.5, 10.0, 60.0):
        assert load.resample(period).charge_ah() == pytest.approx(load.charge_ah())


@pytest.mark.slow
def test_liionpack_per_cell_inputs_reach_the_right_parameters_in_any_order():
    """liionpack passes per-cell inputs by position; the simulator must map them by name."""
    params = load_params(PARAMS / "temi.yaml")
    load = StepLoad.constant(6.0, 300.0)
    n = params.n_cells
    height = np.full(n, 0.85)
    frac = np.full(n, 0.70)
    sim = get_simulator("liionpack")
    a = sim.simulate(params, SimulationRequest(load=load, cell_inputs={
        "Negative electrode active material volume fraction": frac, "Electrode height [m]": height}))
    b = sim.simulate(params, SimulationRequest(load=load, cell_inputs={
        "Electrode height [m]": height, "Negative electrode active material volume fraction": frac}))
    ref = get_simulator("fast").simulate(params.with_values({
        "Electrode height [m]": 0.85, "Negative electrode active material volume fraction": 0.70}),
        SimulationRequest(load=load.resample(10.0)))
    np.testing.assert_allclose(a.pack_voltage_v, b.pack_voltage_v, atol=1e-6)
    np.testing.assert_allclose(a.pack_voltage_v[:-1], ref.pack_voltage_v[: a.time_s.size - 1], atol=0.005)
