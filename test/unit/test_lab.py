"""The emulation lab: seeded real pack, emulated instruments, start-SOC bisection, catalogue and CLI."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.cli.main import main
from battery_predictor.errors import SimulationError
from battery_predictor.lab.experiments import (
    bisect_initial_soc,
    catalogue,
    find_experiments,
    pack_spec,
    standstill_voltage_v,
)
from battery_predictor.lab.instruments import InstrumentSpec, measure, quantise, sample_trace, window_average
from battery_predictor.lab.real_pack import (
    SURFACE_32700_M2,
    PackTrace,
    RealPack,
    RealPackSpec,
    cell_spread,
    real_pack_params,
)
from battery_predictor.params import load_params
from battery_predictor.simulation import SimulationRequest, StepLoad
from battery_predictor.simulation.fast import FastPackSimulator
from battery_predictor.simulation.liionpack_sim import CURRENT_INPUT
from battery_predictor.simulation.liionpack_sim import liionpack_input_name as input_name

PARAMS = Path(__file__).resolve().parents[2] / "params"


@pytest.fixture(scope="module")
def temi():
    return load_params(PARAMS / "temi.yaml")


@pytest.fixture(scope="module")
def ranger():
    return load_params(PARAMS / "ranger_mini.yaml")


# --------------------------------------------------------------------------- real pack


def test_spread_is_seeded_and_deterministic(temi):
    spec = RealPackSpec("p", seed=7)
    a, b = cell_spread(temi, spec), cell_spread(temi, spec)
    other = cell_spread(temi, dataclasses.replace(spec, seed=8))
    assert set(a) == {"Electrode height [m]", "Contact resistance [Ohm]", "Total heat transfer coefficient [W.m-2.K-1]"}
    for key in a:
        assert a[key].shape == (temi.n_cells,)
        np.testing.assert_array_equal(a[key], b[key])
        assert not np.array_equal(a[key], other[key])
    assert np.array_equal(RealPack(temi, spec).cell_inputs["Electrode height [m]"], a["Electrode height [m]"])


def test_spread_has_the_requested_size(temi):
    spec = RealPackSpec("p", seed=3, capacity_sigma=0.015, contact_resistance_mean_ohm=0.003,
                        contact_resistance_sigma_ohm=0.0015)
    big = cell_spread(dataclasses.replace(temi, series=20, parallel=50), spec)
    h0 = temi.value("Electrode height [m]")
    rel = big["Electrode height [m]"] / h0 - 1.0
    assert abs(rel.mean()) < 0.003 and 0.012 < rel.std() < 0.018 and np.abs(rel).max() <= 3 * 0.015 + 1e-12
    r = big["Contact resistance [Ohm]"]
    assert abs(r.mean() - 0.003) < 3e-4 and r.min() >= 0.0003


def test_pack_capacity_factor_scales_the_cells(temi):
    base = cell_spread(temi, RealPackSpec("p", seed=1))
    scaled = cell_spread(temi, RealPackSpec("p", seed=1, pack_capacity_factor=0.97))
    np.testing.assert_allclose(scaled["Electrode height [m]"], 0.97 * base["Electrode height [m]"])


def test_real_pack_params_are_richer_than_spm(temi, ranger):
    rp = real_pack_params(temi, RealPackSpec("p", seed=1))
    assert rp.model == "SPMe"
    assert rp.options["thermal"] == "lumped" and rp.options["contact resistance"] == "true"
    assert temi.model == "SPM" and temi.options == {}  # the params file itself is untouched
    with pytest.raises(SimulationError, match="cooling surface"):
        real_pack_params(ranger, RealPackSpec("p", seed=1))
    pv = real_pack_params(ranger, RealPackSpec("p", seed=1, cooling_surface_area_m2=SURFACE_32700_M2)).parameter_values()
    # Prada2013 has no thermal parameters; the lab supplies them
    for key in ("Positive electrode density [kg.m-3]", "Negative current collector thickness [m]",
                "Total heat transfer coefficient [W.m-2.K-1]", "Cell cooling surface area [m2]"):
        assert float(pv[key]) > 0


def test_inputs_that_sort_before_the_current_are_renamed():
    assert input_name("Contact resistance [Ohm]") > CURRENT_INPUT
    assert input_name("Contact resistance [Ohm]") != "Contact resistance [Ohm]"
    assert input_name("Electrode height [m]") == "Electrode height [m]"
    assert input_name("Total heat transfer coefficient [W.m-2.K-1]") > CURRENT_INPUT






# --------------------------------------------------------------------------- instruments


def _trace(current_a, voltage_v, period_s=5.0, load=None):
    n = len(voltage_v)
    t = np.arange(n) * period_s
    current_a = np.broadcast_to(np.asarray(current_a, dtype=float), (n,)).copy()
    if load is None:
        load = StepLoad(t, current_a, float(t[-1] + period_s))
    temp = 298.15 + 0.01 * np.arange(n)
    return PackTrace(time_s=t, current_a=current_a, voltage_v=np.asarray(voltage_v, dtype=float), temperature_k=temp,
                     cell_temperature_k=temp[:, None], min_cell_voltage_v=np.asarray(voltage_v) / 4,
                     termination="end_of_load", load=load, period_s=period_s, ambient_temperature_k=298.15)


def test_instruments_sample_at_10_hz_and_quantise_before_averaging():
    trace = _trace(2.345, np.linspace(16.0, 15.0, 60))
    m = measure(trace, seed=1)
    raw = m.raw
    np.testing.assert_allclose(np.diff(raw.time_s), 0.1)
    assert raw.time_s.size == 60 * 50
    # quantised to 0.01 V / 0.1 A before averaging
    np.testing.assert_allclose(raw.voltage_v / 0.01, np.round(raw.voltage_v / 0.01), atol=1e-6)
    np.testing.assert_allclose(raw.current_a / 0.1, np.round(raw.current_a / 0.1), atol=1e-6)
    # averaged into 5 s windows labelled by their start
    rec = m.recording
    np.testing.assert_allclose(rec.time_s, np.arange(60) * 5.0)
    for j in (0, 17, 59):
        sel = (raw.time_s >= 5.0 * j - 1e-9) & (raw.time_s < 5.0 * j + 5.0 - 1e-9)
        assert np.count_nonzero(sel) == 50
        assert rec.voltage_v[j] == pytest.approx(raw.voltage_v[sel].mean())
        assert rec.current_a[j] == pytest.approx(raw.current_a[sel].mean())
    # averages are not on the quantisation grid, and they recover sub-resolution values (dithering)
    assert np.mean(np.abs(rec.current_a - 2.345)) < 0.03
    assert np.max(np.abs(rec.voltage_v - trace.voltage_v)) < 0.01


def test_instruments_are_seeded():
    trace = _trace(2.0, np.linspace(16.0, 15.0, 40))
    a, b, c = measure(trace, seed=5), measure(trace, seed=5), measure(trace, seed=6)
    np.testing.assert_array_equal(a.recording.voltage_v, b.recording.voltage_v)
    np.testing.assert_array_equal(a.recording.temperature_k, b.recording.temperature_k)
    assert not np.array_equal(a.recording.voltage_v, c.recording.voltage_v)


def test_thermocouple_noise_and_offset():
    spec = InstrumentSpec()
    trace = _trace(2.0, np.full(200, 15.0))
    raw = sample_trace(trace, spec, np.random.default_rng(3))
    true = np.interp(raw.time_s, trace.time_s, trace.temperature_k)
    err = raw.temperature_k - true
    assert abs(raw.temperature_k.mean() - true.mean() - raw.temperature_offset_k) < 0.02
    assert abs(raw.temperature_offset_k) <= spec.temperature_offset_max_k
    assert 0.4 < np.std(err) < 0.6


def test_intra_step_current_and_voltage_follow_the_bench_supply():
    # 2 A -> 5 A edges in the middle of 5 s steps; the step grid carries the mean current
    load = StepLoad.from_durations([12.5, 10.0, 10.0, 7.5], [2.0, 5.0, 2.0, 5.0])
    stepped = load.resample(5.0)
    v = 16.0 - 0.1 * stepped.current_a  # R = 0.1 Ohm
    trace = _trace(stepped.current_a, v, load=load)
    spec = dataclasses.replace(InstrumentSpec(), voltage_noise_v=0.0, current_noise_a=0.0)
    raw = sample_trace(trace, spec, np.random.default_rng(0))
    assert raw.resistance_ohm == pytest.approx(0.1)
    np.testing.assert_allclose(raw.current_a[raw.time_s < 12.5 - 1e-9], 2.0)
    np.testing.assert_allclose(raw.voltage_v[(raw.time_s > 10) & (raw.time_s < 12.4)], 15.8)
    np.testing.assert_allclose(raw.voltage_v[(raw.time_s > 12.55) & (raw.time_s < 15)], 15.5)


def test_window_average_and_stop_rule():
    t, (x,) = window_average(np.array([0.0, 1.0, 4.9, 5.0, 12.0]), np.array([1.0, 2.0, 3.0, 10.0, 7.0]))
    np.testing.assert_allclose(t, [0.0, 5.0, 10.0])
    np.testing.assert_allclose(x, [2.0, 10.0, 7.0])
    trace = _trace(7.35, np.linspace(12.6, 11.8, 80))
    m = measure(trace, seed=2, stop_voltage_v=12.0)
    rec = m.recording
    assert m.stopped and m.stop_time_s == rec.time_s[-1]
    assert rec.voltage_v[-1] <= 12.0 and np.all(rec.voltage_v[:-1] > 12.0)
    assert m.acquisition_end_s == pytest.approx(rec.time_s[-1] + 5.0)
    assert m.raw.time_s[-1] < m.acquisition_end_s
    assert not measure(trace, seed=2, stop_voltage_v=10.0).stopped


def test_quantise():
    np.testing.assert_allclose(quantise([1.234, 1.235001, -0.04], 0.01), [1.23, 1.24, -0.04])
    np.testing.assert_allclose(quantise([0.149, 0.151], 0.1), [0.1, 0.2])


# --------------------------------------------------------------------------- start SOC bisection


def test_bisection_on_a_synthetic_function():
    calls = []

    def f(soc):
        calls.append(soc)
        return 40.0 + 10.0 * soc if soc > 0.05 else -np.inf

    soc, v, n = bisect_initial_soc(f, 42.5, tol_v=0.001)
    assert v >= 42.5 and v - 42.5 <= 0.001 and soc == pytest.approx(0.25, abs=1e-4)
    assert n == len(calls)
    with pytest.raises(SimulationError):
        bisect_initial_soc(f, 55.0)


def test_bisection_hits_the_target_on_a_cheap_model(temi):
    sim = FastPackSimulator()
    load = StepLoad.from_durations([300.0, 240.0, 60.0], [7.0, 3.0, 1.7])
    grid = np.arange(0.0, load.end_s - 1e-6, 5.0)

    def end_voltage(soc):
        try:
            res = sim.simulate(temi, SimulationRequest(load=load, initial_soc=soc, output_time_s=grid))
        except SimulationError:
            return -np.inf
        if res.reached_cutoff or len(res.time_s) < len(grid):
            return -np.inf
        return standstill_voltage_v(res.time_s, res.pack_voltage_v, load.end_s, 60.0)

    target = 14.2
    soc, v, n = bisect_initial_soc(end_voltage, target, tol_v=0.003)
    assert target <= v <= target + 0.003
    assert end_voltage(soc) == pytest.approx(v)
    assert 0.0 < soc < 1.0 and n < 40
    assert sim.builds == 1  # one build, every evaluation re-solves with new initial concentrations


def test_standstill_voltage_uses_whole_windows_inside_the_standstill():
    t = np.arange(0.0, 100.0, 5.0)
    v = np.where(t >= 40.0, 46.5, 48.0)
    assert standstill_voltage_v(t, v, 100.0, 60.0) == pytest.approx(46.5)
    v2 = v.copy()
    v2[-1] = 46.0
    assert standstill_voltage_v(t, v2, 100.0, 60.0) == pytest.approx((46.5 * 11 + 46.0) / 12)


# --------------------------------------------------------------------------- catalogue and CLI


def test_catalogue_covers_the_paper_experiments():
    cat = catalogue()
    names = [e.name for e in cat]
    assert len(names) == len(set(names)) == 18
    kinds = [e.kind for e in cat]
    assert kinds.count("static") == 1 and kinds.count("dynamic") == 4 and kinds.count("stepwise") == 1
    routes = [e for e in cat if e.kind == "route"]
    assert {(e.pack, e.payload_kg) for e in routes} == {(p, float(kg)) for p in (1, 2, 3) for kg in (20, 40, 60, 80)}
    assert {e.style for e in cat if e.robot == "temi"} == {"relay"}
    assert {e.style for e in cat if e.robot == "ranger_mini"} == {"battery_state"}
    assert len({e.profile_seed for e in cat if e.profile_seed is not None}) == 16
    assert len({pack_spec("temi", p).seed for p in (1, 2, 3, 4)}) == 4
    assert pack_spec("temi", 1) == pack_spec("temi", 1)
    with pytest.raises(Exception, match="unknown experiment"):
        find_experiments(["nope"])


def test_lab_cli_lists_the_catalogue(capsys):
    assert main(["lab", "list", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [e["name"] for e in out["experiments"]] == [e.name for e in catalogue()]
    with pytest.raises(SystemExit):
        main(["lab", "make-bags"])  # --out is required
