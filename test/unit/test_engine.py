"""The SPM engine: PyBaMM's discretised SPM, exact stepping, cut-off, parameter-set scaling, pack voltage."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.engine import pack_voltage_v, series_resistance_factor
from battery_predictor.simulation.engine.modal import boundary_surfaces, modal_system, numba_available
from battery_predictor.simulation.engine.model import (
    C_N0,
    C_P0,
    CURRENT,
    EPS_N,
    EPS_P,
    HEIGHT,
    INPUT_KEYS,
    T_AMB,
    _built_simulation,
    extract_linear_spm,
)
from battery_predictor.simulation.engine.run import (
    ParameterSets,
    run_cells,
    set_surfaces_at_times,
    states_at_times,
    voltages_at_times,
)


@pytest.fixture(scope="module")
def temi_spm(temi_params):
    model = extract_linear_spm(temi_params)
    return model, modal_system(model)


def _uniform_state(model):
    return model.initial_state(model.built_values[C_N0], model.built_values[C_P0])


def test_particle_blocks_reproduce_pybamm_rhs_at_random_states(temi_params, temi_spm):
    model, _ = temi_spm
    built, values, _ = _built_simulation(temi_params)
    rng = np.random.default_rng(1)
    y = rng.uniform(0.2, 0.8, (built.concatenated_rhs.shape[0], 1))
    inputs = {key: values[key] for key in INPUT_KEYS}
    inputs[CURRENT] = 2.5
    for block in model.blocks:
        var = next(v for v in built.y_slices if v.name.startswith(f"X-averaged {block.electrode} particle conc"))
        want = np.asarray(built.rhs[var].evaluate(0.0, y, inputs=inputs)).ravel()
        got = block.a_matrix_per_s @ y[block.state_slice, 0] + block.b_vector_per_a_s * 2.5
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_voltage_function_equals_pybamm_voltage_at_random_states(temi_params, temi_spm):
    model, _ = temi_spm
    built, values, _ = _built_simulation(temi_params)
    rng = np.random.default_rng(2)
    inputs = {key: values[key] for key in INPUT_KEYS}
    for current_a in (-3.0, 0.0, 4.0):
        y = rng.uniform(0.3, 0.8, (built.concatenated_rhs.shape[0], 1))
        inputs[CURRENT] = current_a
        want = float(built.variables["Voltage [V]"].evaluate(0.0, y, inputs=inputs).ravel()[0])
        s_n, s_p = (blk.surface_row @ y[blk.state_slice, 0] for blk in model.blocks)
        got = float(model.cell_voltage_v(s_n, s_p, current_a, values[T_AMB]))
        assert got == pytest.approx(want, abs=1e-12)


def test_modal_zero_order_hold_equals_matrix_exponential(temi_spm):
    model, modal = temi_spm
    rng = np.random.default_rng(3)
    duration_s = rng.uniform(0.5, 30.0, 40)
    current_a = rng.uniform(-2.0, 4.0, 40)
    y_n, y_p = _uniform_state(model)
    z0 = modal.modal_state(y_n, y_p)
    surfaces, _, _ = boundary_surfaces(modal.eigenvalues_per_s[None], modal.input_per_a_s[None], z0, duration_s,
                                       current_a, modal.surface_weights, backend="numpy")
    for k, (block, y) in enumerate(zip(model.blocks, (y_n, y_p))):
        n = y.size
        aug = np.zeros((n + 1, n + 1))
        aug[:n, :n] = block.a_matrix_per_s
        aug[:n, n] = block.b_vector_per_a_s
        state = y.copy()
        for h, i in zip(duration_s, current_a):
            step = scipy.linalg.expm(aug * h)
            state = step[:n, :n] @ state + step[:n, n] * i
        assert surfaces[0, -1, k] == pytest.approx(block.surface_row @ state, rel=1e-11)


def test_uniform_and_varying_step_paths_agree(temi_spm):
    model, modal = temi_spm
    y_n, y_p = _uniform_state(model)
    z0 = modal.modal_state(y_n, y_p)
    current_a = np.random.default_rng(4).uniform(0.0, 3.0, 200)
    args = (modal.eigenvalues_per_s[None], modal.input_per_a_s[None], z0)
    uniform, _, _ = boundary_surfaces(*args, np.full(200, 5.0), current_a, modal.surface_weights, backend="numpy")
    halves = np.repeat(current_a, 2)
    split, _, _ = boundary_surfaces(*args, np.full(400, 2.5), halves, modal.surface_weights, backend="numpy")
    split_two, _, _ = boundary_surfaces(np.repeat(args[0], 2, axis=0), np.repeat(args[1], 2, axis=0),
                                        np.repeat(z0, 2, axis=0), np.full(400, 2.5), halves, modal.surface_weights,
                                        backend="numpy")
    np.testing.assert_allclose(uniform[0], split[0, ::2], rtol=1e-12)
    np.testing.assert_allclose(split_two[1], split[0], rtol=1e-12)


def test_numba_and_numpy_backends_agree(temi_spm):
    pytest.importorskip("numba")
    model, modal = temi_spm
    y_n, y_p = _uniform_state(model)
    z0 = np.repeat(modal.modal_state(y_n, y_p), 3, axis=0)
    lam = modal.eigenvalues_per_s[None] * np.array([[1.0], [0.8], [1.3]])
    drive = np.repeat(modal.input_per_a_s[None], 3, axis=0)
    rng = np.random.default_rng(5)
    duration_s, current_a = rng.uniform(1.0, 10.0, 300), rng.uniform(-1.0, 3.0, 300)
    a = boundary_surfaces(lam, drive, z0, duration_s, current_a, modal.surface_weights, stride=7, backend="numpy")
    b = boundary_surfaces(lam, drive, z0, duration_s, current_a, modal.surface_weights, stride=7, backend="numba")
    for x, y in zip(a, b):
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-15)


def test_run_ends_where_the_voltage_meets_the_cutoff(temi_spm):
    model, modal = temi_spm
    x0_stoich = 0.06  # a nearly empty negative electrode: the cut-off comes within the hour
    c_n0 = x0_stoich * model.blocks[0].scale_mol_m3
    c_p0 = model.built_values[C_P0] + (model.built_values[C_N0] - c_n0) * 0.5
    runs = run_cells(model, modal, np.full(720, 5.0), np.full(720, 2.0), c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                     temperature_k=298.15, keep_states=True)
    assert runs.reached_cutoff[0]
    step = int(runs.cutoff_step[0])
    assert runs.start_voltage_v[0, step] >= model.lower_cutoff_v
    assert 5.0 * step < runs.end_time_s[0] < 5.0 * (step + 1)
    from battery_predictor.simulation.engine.run import voltages_at_times

    v_end = voltages_at_times(model, runs, modal, np.full(720, 5.0), np.full(720, 2.0), runs.end_time_s)
    assert v_end[0, 0] == pytest.approx(model.lower_cutoff_v, abs=1e-8)
    assert np.all(np.isnan(runs.end_voltage_v[0, step:]))


def test_batched_sets_equal_single_runs(temi_spm):
    model, modal = temi_spm
    sets = ParameterSets(radius_n=np.array([1.0, 0.8, 1.2]), diffusivity_p=np.array([1.0, 1.3, 0.7]),
                         fraction_p=np.array([1.0, 0.9, 1.1]), height=np.array([1.0, 1.05, 0.95]))
    current_a = np.random.default_rng(6).uniform(0.0, 4.0, 300)
    common = dict(c_n0_mol_m3=model.built_values[C_N0], c_p0_mol_m3=model.built_values[C_P0], temperature_k=298.15)
    batch = run_cells(model, modal, np.full(300, 5.0), current_a, sets=sets, **common)
    for k in range(3):
        one = ParameterSets(**{key: np.asarray(v)[k] if np.size(v) > 1 else v for key, v in vars(sets).items()})
        single = run_cells(model, modal, np.full(300, 5.0), current_a, sets=one, **common)
        np.testing.assert_allclose(batch.start_voltage_v[k], single.start_voltage_v[0], rtol=1e-12)


@pytest.mark.parametrize("changes, factors", [
    ({"Negative particle radius [m]": 0.8, "Positive particle diffusivity [m2.s-1]": 1.3},
     {"radius_n": 0.8, "diffusivity_p": 1.3}),
    ({"Negative electrode thickness [m]": 1.15, "Positive electrode active material volume fraction": 0.9,
      "Electrode height [m]": 1.1, "Positive particle radius [m]": 1.2},
     {"thickness_n": 1.15, "fraction_p": 0.9, "height": 1.1, "radius_p": 1.2}),
    ({"Maximum concentration in negative electrode [mol.m-3]": 1.1,
      "Maximum concentration in positive electrode [mol.m-3]": 0.93}, {"c_max_n": 1.1, "c_max_p": 0.93}),
])
def test_parameter_set_factors_match_a_pybamm_rebuild(temi_params, temi_spm, changes, factors):
    model, modal = temi_spm
    pv = temi_params.parameter_values()
    rebuilt_params = temi_params.with_values({k: float(pv[k]) * f for k, f in changes.items()})
    rebuilt = extract_linear_spm(rebuilt_params)
    current_a = np.random.default_rng(7).uniform(0.0, 4.0, 120)
    common = dict(c_n0_mol_m3=model.built_values[C_N0], c_p0_mol_m3=model.built_values[C_P0], temperature_k=298.15)
    scaled = run_cells(model, modal, np.full(120, 10.0), current_a, sets=ParameterSets(**factors), **common)
    direct = run_cells(rebuilt, modal_system(rebuilt), np.full(120, 10.0), current_a, **common)
    np.testing.assert_allclose(scaled.start_voltage_v, direct.start_voltage_v, rtol=0, atol=1e-9)


def test_extraction_refuses_a_voltage_that_depends_on_more_than_the_particle_surfaces(temi_params):
    with pytest.raises(SimulationError, match="other than through surface values"):
        extract_linear_spm(temi_params.with_values({}, extensions=("electrolyte_transport",)))


def test_extraction_refuses_a_concentration_dependent_diffusivity(temi_params):
    from dataclasses import replace

    with pytest.raises(SimulationError, match="not linear in the state|depends on the stoichiometry"):
        extract_linear_spm(replace(temi_params, base_parameter_set="Ecker2015", fitted={}, manual={}))


def test_contact_resistance_option_reaches_the_extracted_voltage(temi_params, temi_spm):
    model, _ = temi_spm
    with_contact = extract_linear_spm(temi_params.with_values({"Contact resistance [Ohm]": 0.01},
                                                              extensions=("resistance_growth",)))
    drop = model.cell_voltage_v(0.5, 0.5, 2.0, 298.15) - with_contact.cell_voltage_v(0.5, 0.5, 2.0, 298.15)
    assert drop == pytest.approx(0.02, abs=1e-12)


def test_pack_voltage_is_series_cells_minus_interconnect_drop():
    v = pack_voltage_v(np.array([3.6, 3.5]), np.array([10.0, 0.0]), series=4, r_eq_ohm=0.02)
    np.testing.assert_allclose(v, [4 * 3.6 - 0.2, 4 * 3.5])


def test_pack_voltage_with_a_weak_group_replaces_one_group():
    v = pack_voltage_v(3.6, 5.0, series=4, r_eq_ohm=0.01, weak_cell_voltage_v=3.4)
    assert v == pytest.approx(3 * 3.6 + 3.4 - 0.05)


def test_series_resistance_rises_when_cold_and_is_unchanged_at_reference():
    factor = series_resistance_factor(np.array([298.15, 273.15]), 20000.0)
    assert factor[0] == pytest.approx(1.0)
    assert factor[1] == pytest.approx(np.exp(20000.0 / 8.314462618 * (1 / 273.15 - 1 / 298.15)))
    assert series_resistance_factor(250.0, 0.0) == pytest.approx(1.0)


def test_eps_and_height_inputs_are_the_built_values(temi_params, temi_spm):
    model, _ = temi_spm
    pv = temi_params.parameter_values()
    for key in (EPS_N, EPS_P, HEIGHT):
        assert model.built_values[key] == pytest.approx(float(pv[key]))


def test_fused_kernel_matches_the_numpy_path_including_the_cutoff(temi_spm):
    pytest.importorskip("numba")
    model, modal = temi_spm
    rng = np.random.default_rng(8)
    duration_s = rng.choice([2.0, 5.0, 7.5], 900)
    current_a = rng.uniform(0.0, 2.0, 900)
    c_n0 = np.array([0.08, 0.3, 0.9]) * model.blocks[0].scale_mol_m3
    c_p0 = model.built_values[C_P0] + (model.built_values[C_N0] - c_n0) * 0.5
    sets = ParameterSets(radius_p=np.array([1.0, 1.1, 0.9]), fraction_n=np.array([1.0, 0.85, 1.15]))
    common = dict(c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0, temperature_k=298.15, sets=sets)
    fused = run_cells(model, modal, duration_s, current_a, backend="auto", **common)
    plain = run_cells(model, modal, duration_s, current_a, backend="numpy", **common)
    assert fused.extra["backend"] == "numba-fused"
    assert plain.extra["backend"] == "numpy"
    assert fused.reached_cutoff[0] and not fused.reached_cutoff[2]
    np.testing.assert_array_equal(fused.cutoff_step, plain.cutoff_step)
    np.testing.assert_allclose(fused.end_time_s, plain.end_time_s, rtol=0, atol=1e-6)
    np.testing.assert_allclose(fused.start_voltage_v, plain.start_voltage_v, rtol=0, atol=1e-10)
    np.testing.assert_allclose(fused.end_voltage_v, plain.end_voltage_v, rtol=0, atol=1e-10)


def test_two_pass_path_compiled_voltage_and_root_match_numpy_including_the_cutoff(temi_spm):
    pytest.importorskip("numba")
    model, modal = temi_spm
    rng = np.random.default_rng(9)
    duration_s = rng.choice([2.0, 5.0, 7.5], 900)
    current_a = rng.uniform(0.0, 2.0, 900)
    c_n0 = np.array([0.08, 0.3, 0.9]) * model.blocks[0].scale_mol_m3
    c_p0 = model.built_values[C_P0] + (model.built_values[C_N0] - c_n0) * 0.5
    sets = ParameterSets(radius_p=np.array([1.0, 1.1, 0.9]), fraction_n=np.array([1.0, 0.85, 1.15]))
    common = dict(c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0, temperature_k=298.15, sets=sets, keep_states=True)
    compiled = run_cells(model, modal, duration_s, current_a, backend="auto", **common)
    plain = run_cells(model, modal, duration_s, current_a, backend="numpy", **common)
    assert compiled.extra["kernels"] is not None and plain.extra["kernels"] is None
    assert compiled.reached_cutoff[0] and not compiled.reached_cutoff[2]
    np.testing.assert_array_equal(compiled.cutoff_step, plain.cutoff_step)
    np.testing.assert_allclose(compiled.end_time_s, plain.end_time_s, rtol=0, atol=1e-6)
    np.testing.assert_allclose(compiled.start_voltage_v, plain.start_voltage_v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(compiled.end_voltage_v, plain.end_voltage_v, rtol=0, atol=1e-12)
    times = np.sort(rng.uniform(0.0, compiled.end_time_s.min(), 300))
    np.testing.assert_allclose(voltages_at_times(model, compiled, modal, duration_s, current_a, times),
                               voltages_at_times(model, plain, modal, duration_s, current_a, times), rtol=0, atol=1e-12)
    for s in range(3):
        np.testing.assert_allclose(set_surfaces_at_times(compiled, modal, duration_s, current_a, times, s),
                                   states_at_times(plain, modal, duration_s, current_a, times)[s], rtol=0, atol=1e-14)


class _StubSimulator:
    name = "stub"

    def simulate(self, params, request):
        from battery_predictor.simulation.base import PackSimResult

        return PackSimResult(np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), "end_of_load", 0.0)


def test_simulator_falls_back_visibly_for_what_the_engine_does_not_cover(temi_params, caplog):
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.engine.simulator import EngineSimulator

    request = SimulationRequest(load=StepLoad.constant(3.0, 60.0), initial_soc=0.5)
    params = temi_params.with_values({}, extensions=("electrolyte_transport",))
    with caplog.at_level("WARNING"):
        result = EngineSimulator(fallback=_StubSimulator()).simulate(params, request)
    assert result.extra["engine_fallback"].startswith("stub: ")
    assert "simulating with the stub simulator" in caplog.text
    with pytest.raises(SimulationError, match="engine: "):
        EngineSimulator(fallback=None).simulate(params, request)


def test_simulator_reuses_one_extraction_for_scalable_parameter_changes(temi_params):
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.engine.simulator import EngineSimulator

    sim = EngineSimulator(fallback=None)
    request = SimulationRequest(load=StepLoad.constant(6.0, 600.0), initial_soc=0.5)
    base = sim.simulate(temi_params, request)
    thinner = sim.simulate(temi_params.with_values({"Positive electrode thickness [m]": 1.0e-4,
                                                    "Electrode height [m]": 0.85}), request)
    assert sim.extractions == 1
    assert base.extra["engine_seconds"] < base.seconds
    assert thinner.pack_voltage_v[-1] < base.pack_voltage_v[-1]  # less positive material: deeper discharge


@pytest.mark.parametrize("soc, ocv_v", [(0.0, None), (0.35, None), (1.0, None), (None, 3.7)])
def test_initial_state_matches_pybamm_get_initial_stoichiometries(temi_params, temi_spm, soc, ocv_v):
    from battery_predictor.simulation.cell_setup import initial_concentrations, prepared_parameter_values
    from battery_predictor.simulation.engine.state import StoichiometryWindow

    model, _ = temi_spm
    pv = prepared_parameter_values(temi_params)
    got = StoichiometryWindow(model, pv).concentrations(soc=soc, ocv_v=ocv_v)
    want = initial_concentrations(temi_params, pv, initial_soc=soc, initial_cell_ocv_v=ocv_v)
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_initial_state_refuses_an_unreachable_voltage(temi_params, temi_spm):
    from battery_predictor.simulation.cell_setup import prepared_parameter_values
    from battery_predictor.simulation.engine.state import StoichiometryWindow

    model, _ = temi_spm
    with pytest.raises(SimulationError, match="open-circuit voltage of 6.0000 V"):
        StoichiometryWindow(model, prepared_parameter_values(temi_params)).concentrations(ocv_v=6.0)


def test_batch_equals_one_simulation_per_set(temi_params):
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.engine.simulator import EngineSimulator

    sim = EngineSimulator(fallback=None)
    load = StepLoad.from_durations(np.full(120, 5.0), np.random.default_rng(9).uniform(5.0, 25.0, 120))
    request = SimulationRequest(load=load, initial_soc=0.3, output_time_s=load.start_s)
    values = {HEIGHT: np.array([0.85, 0.9]), "Negative electrode thickness [m]": np.array([1.1e-4, 1.3e-4])}
    batch = sim.simulate_batch(temi_params, request, values)
    for k in range(2):
        one = sim.simulate(temi_params.with_values({key: float(v[k]) for key, v in values.items()}), request)
        assert batch.end_time_s[k] == pytest.approx(one.end_time_s, abs=1e-6)
        n = one.time_s.size
        np.testing.assert_allclose(batch.pack_voltage_v[k, :n], one.pack_voltage_v, rtol=0, atol=1e-9)
    assert sim.extractions == 1


def test_batch_refuses_a_value_that_needs_a_rebuild(temi_params):
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.engine.simulator import EngineSimulator

    request = SimulationRequest(load=StepLoad.constant(3.0, 60.0))
    with pytest.raises(SimulationError, match="Electrode width"):
        EngineSimulator(fallback=None).simulate_batch(temi_params, request,
                                                      {"Electrode width [m]": np.array([0.05, 0.06])})


@pytest.mark.parametrize("name", ["temi", "ranger_mini"])
def test_maximum_concentration_rule_holds_for_the_shipped_packs(name):
    from battery_predictor.params import load_params
    from battery_predictor.simulation.engine.model import c_max_scaling_holds

    assert c_max_scaling_holds(load_params(Path(__file__).resolve().parents[2] / "params" / f"{name}.yaml"))


def test_simulator_scales_a_maximum_concentration_without_a_new_extraction(temi_params):
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.engine.simulator import EngineSimulator

    request = SimulationRequest(load=StepLoad.constant(6.0, 1800.0), initial_soc=0.4,
                                output_time_s=np.arange(0, 1800, 60.0))
    sim = EngineSimulator(fallback=None)
    sim.simulate(temi_params, request)
    changed = temi_params.with_values({"Maximum concentration in positive electrode [mol.m-3]": 80000.0})
    scaled = sim.simulate(changed, request)
    direct = EngineSimulator(fallback=None, cache_size=1)
    direct._c_max_rule[(changed.base_parameter_set, changed.model, "[]", changed.extensions)] = False
    rebuilt = direct.simulate(changed, request)
    assert sim.extractions == 1
    np.testing.assert_allclose(scaled.pack_voltage_v, rebuilt.pack_voltage_v, rtol=0, atol=1e-8)


@pytest.mark.parametrize("backend", ["auto", "numpy"])
def test_a_run_continued_from_its_final_state_equals_one_run(temi_spm, backend):
    model, modal = temi_spm
    rng = np.random.default_rng(10)
    duration_s, current_a = rng.uniform(2.0, 8.0, 400), rng.uniform(-1.0, 3.0, 400)
    common = dict(temperature_k=298.15, backend=backend)
    whole = run_cells(model, modal, duration_s, current_a, c_n0_mol_m3=model.built_values[C_N0],
                      c_p0_mol_m3=model.built_values[C_P0], **common)
    first = run_cells(model, modal, duration_s[:150], current_a[:150], c_n0_mol_m3=model.built_values[C_N0],
                      c_p0_mol_m3=model.built_values[C_P0], **common)
    rest = run_cells(model, modal, duration_s[150:], current_a[150:], initial_state=first.final_state, **common)
    np.testing.assert_allclose(np.concatenate([first.start_voltage_v[0], rest.start_voltage_v[0]]),
                               whole.start_voltage_v[0], rtol=0, atol=1e-10)
    for got, want in zip(rest.final_state, whole.final_state):
        np.testing.assert_allclose(got, want, rtol=1e-10)


def test_final_state_at_the_cutoff_is_at_the_cutoff_voltage(temi_spm):
    model, modal = temi_spm
    c_n0 = 0.06 * model.blocks[0].scale_mol_m3
    c_p0 = model.built_values[C_P0] + (model.built_values[C_N0] - c_n0) * 0.5
    runs = run_cells(model, modal, np.full(720, 5.0), np.full(720, 2.0), c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                     temperature_k=298.15)
    assert runs.reached_cutoff[0]
    y_n, y_p = runs.final_state
    v = model.cell_voltage_v(model.blocks[0].surface_row @ y_n[0], model.blocks[1].surface_row @ y_p[0], 2.0, 298.15)
    assert float(v) == pytest.approx(model.lower_cutoff_v, abs=1e-8)


def test_without_numba_the_numpy_path_runs_and_agrees(temi_spm, monkeypatch):
    model, modal = temi_spm
    rng = np.random.default_rng(11)
    duration_s, current_a = np.full(300, 5.0), rng.uniform(0.0, 4.0, 300)
    common = dict(c_n0_mol_m3=0.1 * model.blocks[0].scale_mol_m3, c_p0_mol_m3=model.built_values[C_P0] * 1.3,
                  temperature_k=298.15)
    with_numba = run_cells(model, modal, duration_s, current_a, **common)
    monkeypatch.setitem(__import__("sys").modules, "numba", None)  # import numba now raises ImportError
    without = run_cells(model, modal, duration_s, current_a, **common)
    assert without.extra["backend"] == "numpy"
    assert with_numba.reached_cutoff[0] and without.reached_cutoff[0]
    np.testing.assert_allclose(without.end_time_s, with_numba.end_time_s, rtol=0, atol=1e-6)
    np.testing.assert_allclose(without.start_voltage_v, with_numba.start_voltage_v, rtol=0, atol=1e-10)


def test_a_voltage_without_a_scalar_form_runs_on_the_numpy_voltage(temi_spm, monkeypatch):
    from battery_predictor.simulation.engine import run as run_module

    model, modal = temi_spm
    monkeypatch.setattr(run_module, "fused_kernel", lambda *args, **kwargs: None)
    monkeypatch.setattr(run_module, "voltage_kernels", lambda *args, **kwargs: None)
    runs = run_cells(model, modal, np.full(50, 5.0), np.full(50, 2.0), c_n0_mol_m3=model.built_values[C_N0],
                     c_p0_mol_m3=model.built_values[C_P0], temperature_k=298.15)
    assert runs.extra["backend"] in ("numba", "numpy")
    assert np.all(np.isfinite(runs.start_voltage_v))


def test_simulator_reports_step_starts_from_the_fused_run_as_from_kept_states(temi_params):
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.engine.simulator import EngineSimulator

    load = StepLoad.from_durations(np.full(400, 5.0), np.random.default_rng(12).uniform(5.0, 30.0, 400))
    sim = EngineSimulator(fallback=None)
    on_starts = sim.simulate(temi_params, SimulationRequest(load=load, initial_soc=0.2, output_time_s=load.start_s))
    with_mids = sim.simulate(temi_params, SimulationRequest(load=load, initial_soc=0.2,
                                                            output_time_s=np.append(load.start_s, 2.5)))
    assert on_starts.termination == with_mids.termination == "cell_cutoff"
    assert on_starts.extra["engine_backend"] == ("numba-fused" if numba_available() else "numpy")
    assert on_starts.end_time_s == pytest.approx(with_mids.end_time_s, abs=1e-6)
    n = on_starts.time_s.size
    np.testing.assert_array_equal(with_mids.time_s[:n], on_starts.time_s)
    np.testing.assert_allclose(on_starts.pack_voltage_v, with_mids.pack_voltage_v[:n], rtol=0, atol=1e-9)


def test_a_kernel_that_does_not_compile_falls_back_to_the_two_pass_path(temi_params, caplog):
    numba = pytest.importorskip("numba")
    from battery_predictor.simulation.engine import run as run_module

    model = extract_linear_spm(temi_params)
    modal = modal_system(model)

    def broken(*args):
        raise numba.core.errors.TypingError("no typing for this expression")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(run_module, "fused_kernel", lambda *args, **kwargs: broken)
        with caplog.at_level("WARNING"):
            runs = run_cells(model, modal, np.full(50, 5.0), np.full(50, 2.0), c_n0_mol_m3=model.built_values[C_N0],
                             c_p0_mol_m3=model.built_values[C_P0], temperature_k=298.15)
    assert runs.extra["backend"] == "numba"
    assert "does not compile" in caplog.text
    from battery_predictor.simulation.engine.kernel import fused_kernel

    assert fused_kernel(model) is None


def test_the_package_exposes_the_simulator_and_the_segment_runner():
    import battery_predictor.simulation.engine as engine_package
    from battery_predictor.simulation.engine.segments import EnginePack
    from battery_predictor.simulation.engine.simulator import EngineSimulator

    assert engine_package.EngineSimulator is EngineSimulator
    assert engine_package.EnginePack is EnginePack
    with pytest.raises(AttributeError):
        engine_package.NoSuchName  # noqa: B018


@pytest.mark.parametrize("backend", ["auto", "numpy"])
def test_charging_a_full_cell_past_its_range_is_an_error_not_a_voltage(temi_spm, backend):
    model, modal = temi_spm
    c_n0 = 0.995 * model.blocks[0].scale_mol_m3  # a full negative electrode ...
    c_p0 = 0.05 * model.blocks[1].scale_mol_m3
    with pytest.raises(SimulationError, match="charged past full"):  # ... charged for an hour at 5 A per cell
        run_cells(model, modal, np.full(720, 5.0), np.full(720, -5.0), c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                  temperature_k=298.15, backend=backend)
