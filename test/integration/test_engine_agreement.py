"""The engine against PyBaMM's own SPM solved by IDAKLU at rtol = atol = 1e-10 on short profiles.

Issue 18's bar: <= 0.1 mV RMS pack voltage and the time to cut-off within 0.02 %, on a Temi-like
profile, a Ranger-like profile and a real drive-cycle excerpt. The reference is the fast
simulator's PyBaMM solution (current as an interpolant), evaluated at the engine's report times:
every step start (right-continuous: the step's current) and every step middle.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.simulation import SimulationRequest, StepLoad
from battery_predictor.simulation.engine import pack_voltage_v
from battery_predictor.simulation.engine.simulator import EngineSimulator
from battery_predictor.simulation.fast import FastPackSimulator

REPO = Path(__file__).resolve().parents[2]
US06 = REPO.parent / "shared" / "data" / "panasonic_18650pf" / "drive_T25C_US06.csv"
RMS_LIMIT_V = 1e-4
CUTOFF_LIMIT_FRACTION = 2e-4


def _report_times(load: StepLoad) -> np.ndarray:
    mids = load.start_s + 0.5 * np.diff(load.edges_s())
    return np.sort(np.concatenate([load.start_s, mids]))


def _compare(params, load: StepLoad, initial_soc: float) -> tuple[float, float, object]:
    """(RMS pack-voltage difference in V, relative cut-off time difference, engine result)."""
    request = SimulationRequest(load=load, initial_soc=initial_soc, output_time_s=_report_times(load))
    engine = EngineSimulator(fallback=None).simulate(params, request)
    reference = FastPackSimulator(rtol=1e-10, atol=1e-10).simulate(params, request)
    solution = reference.extra["solution"]
    t = engine.time_s
    v_cell = np.asarray(solution["Terminal voltage [V]"](t), dtype=float)
    v_ref = pack_voltage_v(v_cell, load.current_at(t), series=params.series, r_eq_ohm=reference.extra["r_eq_ohm"])
    rms_v = float(np.sqrt(np.mean((engine.pack_voltage_v - v_ref) ** 2)))
    cutoff_fraction = abs(engine.end_time_s - reference.end_time_s) / reference.end_time_s
    assert engine.termination == reference.termination == "cell_cutoff"
    return rms_v, cutoff_fraction, engine


def test_engine_matches_pybamm_on_a_temi_like_profile(temi_params):
    from battery_predictor.profiles.temi import generate_usage_profile

    load = StepLoad.from_profile(generate_usage_profile(seed=1, max_duration_s=2400)).scale_current(4.0).resample(5.0)
    rms_v, cutoff_fraction, _ = _compare(temi_params, load, initial_soc=0.15)
    assert rms_v <= RMS_LIMIT_V
    assert cutoff_fraction <= CUTOFF_LIMIT_FRACTION


def test_engine_matches_pybamm_on_a_ranger_like_route():
    from battery_predictor.profiles.ranger import longest_route, route_profile

    params = load_params(REPO / "params" / "ranger_mini.yaml")
    load = StepLoad.from_profile(route_profile(longest_route(80.0), seed=0)).scale_current(2.0)
    rms_v, cutoff_fraction, _ = _compare(params, load, initial_soc=0.03)
    assert rms_v <= RMS_LIMIT_V
    assert cutoff_fraction <= CUTOFF_LIMIT_FRACTION


@pytest.mark.skipif(not US06.exists(), reason="the Panasonic 18650PF data set is not beside the repository")
def test_engine_matches_pybamm_on_a_us06_drive_cycle_excerpt():
    params = load_params(REPO / "params" / "panasonic_18650pf.yaml")
    data = np.genfromtxt(US06, delimiter=",", names=True)
    keep = data["time_s"] <= 1200.0
    load = StepLoad.from_samples(data["time_s"][keep], data["current_A"][keep])
    rms_v, cutoff_fraction, engine = _compare(params, load, initial_soc=0.2)
    assert np.unique(np.round(np.diff(load.edges_s()), 6)).size > 1  # the varying-step path ran
    assert rms_v <= RMS_LIMIT_V
    assert cutoff_fraction <= CUTOFF_LIMIT_FRACTION


def test_engine_matches_pybamm_with_a_contact_resistance(temi_params):
    from battery_predictor.profiles.temi import generate_usage_profile

    params = temi_params.with_values({"Contact resistance [Ohm]": 0.02}, extensions=("resistance_growth",))
    load = StepLoad.from_profile(generate_usage_profile(seed=2, max_duration_s=1800)).scale_current(4.0).resample(5.0)
    rms_v, cutoff_fraction, engine = _compare(params, load, initial_soc=0.12)
    assert "engine_fallback" not in engine.extra
    assert rms_v <= RMS_LIMIT_V
    assert cutoff_fraction <= CUTOFF_LIMIT_FRACTION


def test_engine_matches_pybamm_with_temperature_dependent_diffusivities_away_from_the_build(temi_params):
    from dataclasses import replace

    from battery_predictor.profiles.temi import generate_usage_profile

    params = replace(temi_params, base_parameter_set="NCA_Kim2011", fitted={}, manual={})
    load = StepLoad.from_profile(generate_usage_profile(seed=3, max_duration_s=1800)).resample(5.0)
    request = SimulationRequest(load=load, initial_soc=0.5, ambient_temperature_k=283.15,
                                output_time_s=_report_times(load))
    engine = EngineSimulator(fallback=None).simulate(params, request)
    reference = FastPackSimulator(rtol=1e-10, atol=1e-10).simulate(params, request)
    v_cell = np.asarray(reference.extra["solution"]["Terminal voltage [V]"](engine.time_s), dtype=float)
    v_ref = pack_voltage_v(v_cell, load.current_at(engine.time_s), series=params.series,
                           r_eq_ohm=reference.extra["r_eq_ohm"])
    assert float(np.sqrt(np.mean((engine.pack_voltage_v - v_ref) ** 2))) <= RMS_LIMIT_V


def test_engine_runs_a_weak_series_group_as_pybamm_does(temi_params):
    """Extension ``cell_imbalance``: the weak group is a second set of the same extraction; the pack ends
    when its cell reaches the cut-off, with the others' still above it."""
    from dataclasses import replace

    from battery_predictor.profiles.temi import generate_usage_profile
    from battery_predictor.simulation.extensions import WEAK_FRACTION

    params = replace(temi_params, extensions=("cell_imbalance",), extra={**temi_params.extra, WEAK_FRACTION: 0.8})
    load = StepLoad.from_profile(generate_usage_profile(seed=4, max_duration_s=2400)).scale_current(4.0).resample(5.0)
    request = SimulationRequest(load=load, initial_soc=0.2, output_time_s=_report_times(load))
    engine = EngineSimulator(fallback=None).simulate(params, request)
    reference = FastPackSimulator(rtol=1e-10, atol=1e-10).simulate(params, request)
    assert "engine_fallback" not in engine.extra
    assert engine.termination == reference.termination == "cell_cutoff"
    n = min(engine.time_s.size, reference.time_s.size) - 1  # the last report time sits on the cut-off
    np.testing.assert_allclose(engine.time_s[:n], reference.time_s[:n])
    rms_v = float(np.sqrt(np.mean((engine.pack_voltage_v[:n] - reference.pack_voltage_v[:n]) ** 2)))
    assert rms_v <= RMS_LIMIT_V
    assert abs(engine.end_time_s - reference.end_time_s) / reference.end_time_s <= CUTOFF_LIMIT_FRACTION
    # the weak cell ended the run: the other cells are still well above it
    v_weak = engine.min_cell_voltage_v[-1]
    v_others = (engine.pack_voltage_v[-1] + engine.pack_current_a[-1] * float(engine.extra["r_eq_ohm"]) - v_weak) \
        / (params.series - 1)
    assert v_others > v_weak + 0.05
