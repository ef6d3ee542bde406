"""The engine's lumped thermal cell against PyBaMM's own SPM with ``{"thermal": "lumped"}``.

The reference is the fast simulator's PyBaMM solution at rtol = atol = 1e-10 (the current an
interpolant), read at the engine's report times. Bars: pack voltage <= 0.1 mV RMS, cell temperature
<= 0.01 K RMS, time to cut-off within 0.02 % (issue 18's voltage and cut-off bars; the temperature
bar is about a hundredth of the rises below). Measured figures are in BENCHMARKS.md.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from battery_predictor.simulation import SimulationRequest, StepLoad
from battery_predictor.simulation.engine import pack_voltage_v
from battery_predictor.simulation.engine.simulator import EngineSimulator
from battery_predictor.simulation.fast import FastPackSimulator

RMS_LIMIT_V = 1e-4
TEMPERATURE_RMS_LIMIT_K = 1e-2
CUTOFF_LIMIT_FRACTION = 2e-4
LUMPED = {"thermal": "lumped"}
ARRHENIUS = {
    "Negative particle diffusivity activation energy [J.mol-1]": 30000.0,
    "Positive particle diffusivity activation energy [J.mol-1]": 25000.0,
    "Series resistance activation energy [J.mol-1]": 20000.0,
}


@pytest.fixture(scope="module")
def thermal_temi(temi_params):
    return replace(temi_params, options=LUMPED)


def _compare(params, load: StepLoad, initial_soc: float, output_time_s=None, backend: str = "auto"):
    """(pack-voltage RMS in V, temperature RMS in K, relative cut-off difference, temperature rise in K, engine)."""
    if output_time_s is None:
        mids = load.start_s + 0.5 * np.diff(load.edges_s())
        output_time_s = np.sort(np.concatenate([load.start_s, mids]))
    request = SimulationRequest(load=load, initial_soc=initial_soc, output_time_s=output_time_s)
    engine = EngineSimulator(fallback=None, backend=backend).simulate(params, request)
    reference = FastPackSimulator(rtol=1e-10, atol=1e-10).simulate(params, request)
    solution = reference.extra["solution"]
    t = engine.time_s
    v_cell = np.asarray(solution["Terminal voltage [V]"](t), dtype=float)
    t_ref = np.asarray(solution["Volume-averaged cell temperature [K]"](t), dtype=float)
    r_eq = reference.extra["r_eq_ohm"]
    if np.ndim(r_eq):  # the temperature extension's factor, at the reference's report times
        r_eq = np.interp(t, reference.time_s, r_eq)
    v_ref = pack_voltage_v(v_cell, load.current_at(t), series=params.series, r_eq_ohm=r_eq)
    rms_v = float(np.sqrt(np.mean((engine.pack_voltage_v - v_ref) ** 2)))
    rms_k = float(np.sqrt(np.mean((engine.extra["cell_temperature_k"] - t_ref) ** 2)))
    assert engine.termination == reference.termination
    cutoff = abs(engine.end_time_s - reference.end_time_s) / reference.end_time_s
    return rms_v, rms_k, cutoff, float(t_ref.max() - t_ref[0]), engine


def _temi_day(seconds: float, scale: float, step_s: float) -> StepLoad:
    from battery_predictor.profiles.temi import generate_usage_profile

    return StepLoad.from_profile(generate_usage_profile(seed=1, max_duration_s=seconds)).scale_current(scale).resample(
        step_s)


def test_thermal_engine_matches_pybamm_lumped_on_a_temi_like_profile(thermal_temi):
    rms_v, rms_k, cutoff, rise_k, engine = _compare(thermal_temi, _temi_day(2400.0, 8.0, 5.0), initial_soc=0.5)
    assert engine.extra["thermal"] == "lumped" and engine.extra["engine_backend"].endswith("-thermal")
    assert engine.reached_cutoff
    assert rise_k > 3.0  # the profile heats the cell noticeably
    assert rms_v <= RMS_LIMIT_V
    assert rms_k <= TEMPERATURE_RMS_LIMIT_K
    assert cutoff <= CUTOFF_LIMIT_FRACTION


def test_one_long_constant_current_step_is_split_for_the_temperature_and_matches_pybamm(thermal_temi):
    load = StepLoad.constant(2.0 * 14.7, 3600.0)  # 2C, one step, about 10 K of self-heating
    rms_v, rms_k, cutoff, rise_k, _ = _compare(thermal_temi, load, 1.0, output_time_s=np.arange(0.0, 3600.0, 7.0))
    assert rise_k > 8.0
    assert rms_v <= RMS_LIMIT_V
    assert rms_k <= TEMPERATURE_RMS_LIMIT_K
    assert cutoff <= CUTOFF_LIMIT_FRACTION


def test_arrhenius_diffusivities_and_series_resistance_follow_the_cell_temperature(thermal_temi):
    params = replace(thermal_temi, extensions=("temperature",), extra={**thermal_temi.extra, **ARRHENIUS})
    load = StepLoad.constant(2.0 * 14.7, 3600.0)
    rms_v, rms_k, cutoff, rise_k, engine = _compare(params, load, 1.0, output_time_s=np.arange(0.0, 3600.0, 7.0))
    assert "engine_fallback" not in engine.extra
    assert rise_k > 8.0  # diffusivities rise by about 40 % over the run
    assert rms_v <= RMS_LIMIT_V
    assert rms_k <= TEMPERATURE_RMS_LIMIT_K
    assert cutoff <= CUTOFF_LIMIT_FRACTION


def test_numpy_and_compiled_thermal_paths_agree(thermal_temi):
    pytest.importorskip("numba")
    load = _temi_day(1200.0, 8.0, 5.0)
    request = SimulationRequest(load=load, initial_soc=0.6)
    compiled = EngineSimulator(fallback=None, backend="auto").simulate(thermal_temi, request)
    numpy_run = EngineSimulator(fallback=None, backend="numpy").simulate(thermal_temi, request)
    assert compiled.extra["engine_backend"] == "numba-thermal"
    assert numpy_run.extra["engine_backend"] == "numpy-thermal"
    np.testing.assert_allclose(compiled.pack_voltage_v, numpy_run.pack_voltage_v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(compiled.extra["cell_temperature_k"], numpy_run.extra["cell_temperature_k"], rtol=0,
                               atol=1e-9)


def test_isothermal_params_stay_isothermal(temi_params):
    request = SimulationRequest(load=_temi_day(600.0, 4.0, 5.0), initial_soc=0.6)
    result = EngineSimulator(fallback=None).simulate(temi_params, request)
    assert result.extra["thermal"] == "isothermal"
    assert "cell_temperature_k" not in result.extra


def test_a_thermal_batch_equals_single_thermal_runs(thermal_temi):
    load = _temi_day(1200.0, 8.0, 5.0)
    request = SimulationRequest(load=load, initial_soc=0.6)
    sim = EngineSimulator(fallback=None)
    key = "Negative particle diffusivity [m2.s-1]"
    values = {key: np.array([2e-14, 3.3e-14, 5e-14])}
    batch = sim.simulate_batch(thermal_temi, request, values)
    for k, d in enumerate(values[key]):
        single = sim.simulate(thermal_temi.with_values({key: float(d)}), request)
        n = single.time_s.size
        np.testing.assert_allclose(batch.pack_voltage_v[k, :n], single.pack_voltage_v, rtol=0, atol=1e-9)


def test_engine_pack_carries_the_cell_temperature_and_matches_the_pybamm_runner(thermal_temi):
    from battery_predictor.prediction.cell_runner import PackRunner
    from battery_predictor.simulation.engine.segments import EnginePack

    segments = [(600.0, 2.0 * 14.7), (300.0, 0.5), (900.0, 1.5 * 14.7)]
    pack = EnginePack(thermal_temi)
    whole = pack.run(0.9, segments, 298.15)
    first = pack.run(0.9, segments[:1], 298.15)
    rest = pack.run(first.final_state, segments[1:], 298.15)
    assert first.final_state.cell_temperature_k[0] > 303.0  # 10 min at 2C heated the cell
    np.testing.assert_allclose(rest.pack_voltage_v[-3:], whole.pack_voltage_v[-3:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(rest.final_state.cell_temperature_k, whole.final_state.cell_temperature_k, atol=1e-9)
    runner = PackRunner(thermal_temi).run(0.9, segments, 298.15)
    np.testing.assert_allclose(whole.time_s, runner.time_s, rtol=0, atol=1e-6)
    np.testing.assert_allclose(whole.pack_voltage_v, runner.pack_voltage_v, rtol=0, atol=2e-4)
    temperature = runner.final_state.solution["Volume-averaged cell temperature [K]"].entries[-1]
    assert whole.final_state.cell_temperature_k[0] == pytest.approx(float(temperature), abs=1e-3)


def test_thicker_electrodes_scale_the_heat_capacity_as_a_pybamm_rebuild(thermal_temi):
    load = StepLoad.constant(2.0 * 14.7, 3600.0)
    request = SimulationRequest(load=load, initial_soc=1.0, output_time_s=np.arange(0.0, 3600.0, 7.0))
    sim = EngineSimulator(fallback=None)
    sim.simulate(thermal_temi, request)
    thicker = thermal_temi.with_values({"Negative electrode thickness [m]": 1.2137e-04 * 1.3,
                                        "Positive electrode thickness [m]": 1.1049e-04 * 0.8})
    scaled = sim.simulate(thicker, request)
    assert sim.extractions == 1  # the thicknesses were scaled, not rebuilt
    rebuilt = EngineSimulator(fallback=None).simulate(thicker, request)
    np.testing.assert_allclose(scaled.extra["cell_temperature_k"], rebuilt.extra["cell_temperature_k"], rtol=0,
                               atol=1e-9)
    np.testing.assert_allclose(scaled.pack_voltage_v, rebuilt.pack_voltage_v, rtol=0, atol=1e-9)


def test_a_thermal_run_without_every_state_kept_ends_where_one_with_them_does(thermal_temi):
    load = _temi_day(2400.0, 8.0, 5.0)
    sim = EngineSimulator(fallback=None)
    on_starts = sim.simulate(thermal_temi, SimulationRequest(load=load, initial_soc=0.5))  # states every 64 steps
    inside = sim.simulate(thermal_temi, SimulationRequest(load=load, initial_soc=0.5,
                                                          output_time_s=load.start_s + 1.0))  # every state kept
    assert on_starts.reached_cutoff and inside.reached_cutoff
    assert on_starts.end_time_s == pytest.approx(inside.end_time_s, abs=1e-6)


def test_simulate_cli_runs_the_lumped_cell_when_asked(temi_params, tmp_path, capsys):
    import json
    import warnings
    from pathlib import Path

    from battery_predictor.cli.main import main

    load = StepLoad.constant(0.0, 60.0).append(_temi_day(1800.0, 8.0, 5.0))  # at rest first: the OCV
    thermal = replace(temi_params, options=LUMPED)
    truth = EngineSimulator(fallback=None).simulate(thermal, SimulationRequest(load=load, initial_soc=0.8))
    csv = tmp_path / "day.csv"
    rows = np.column_stack([truth.time_s, truth.pack_voltage_v, truth.pack_current_a])
    np.savetxt(csv, rows, delimiter=",", header="time_s,voltage_V,current_A", comments="", fmt="%.6f")
    params_file = str(Path(__file__).parents[2] / "params" / "temi.yaml")
    out = {}
    for mode in ("params", "lumped"):
        with warnings.catch_warnings():  # the CLI sets its own warning filters
            code = main(["simulate", "--params", params_file, "--data", str(csv), "--thermal", mode,
                         "--initial-state", "voltage", "--json"])
        assert code == 0
        out[mode] = json.loads(capsys.readouterr().out)
    assert out["params"]["thermal"] == "isothermal" and out["lumped"]["thermal"] == "lumped"
    assert out["lumped"]["rmse_mV"] < out["params"]["rmse_mV"]  # the data were made by the lumped cell
