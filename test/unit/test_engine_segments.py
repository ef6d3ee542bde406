"""Segment runs on the engine (EnginePack) against the predictor's PyBaMM pack model (PackRunner)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.engine.segments import EnginePack, EngineState

REPO = Path(__file__).resolve().parents[2]
#: PackRunner solves at rtol 1e-6 / atol 1e-8; the engine is exact for the same discretised model.
PACK_TOLERANCE_V = 1e-4


def test_route_from_an_soc_matches_the_pybamm_pack_model(ranger_params, longest_route_segments):
    from battery_predictor.prediction.cell_runner import PackRunner

    engine = EnginePack(ranger_params).run(0.3, longest_route_segments, 298.15)
    pybamm_run = PackRunner(ranger_params).run(0.3, longest_route_segments, 298.15)
    np.testing.assert_allclose(engine.time_s, pybamm_run.time_s, rtol=0, atol=1e-6)
    np.testing.assert_allclose(engine.pack_voltage_v, pybamm_run.pack_voltage_v, rtol=0, atol=PACK_TOLERANCE_V)
    assert engine.segment_end_index == pybamm_run.segment_end_index
    assert not engine.reached_cutoff and not pybamm_run.reached_cutoff


def test_soc_window_and_capacity_match_the_pybamm_pack_model(ranger_params):
    from battery_predictor.prediction.cell_runner import PackRunner

    engine, runner = EnginePack(ranger_params), PackRunner(ranger_params)
    assert engine.capacity_ah == pytest.approx(runner.capacity_ah, rel=1e-6)
    np.testing.assert_allclose(engine.soc_bounds, runner.soc_bounds, rtol=1e-6)
    np.testing.assert_allclose(engine.concentrations(0.4), runner.concentrations(0.4), rtol=1e-9)


def test_a_continued_run_equals_one_run(ranger_params, longest_route_segments):
    pack = EnginePack(ranger_params)
    whole = pack.run(0.5, longest_route_segments, 298.15)
    first = pack.run(0.5, longest_route_segments[:40], 298.15)
    rest = pack.run(first.final_state, longest_route_segments[40:], 298.15)
    np.testing.assert_allclose(rest.pack_voltage_v[-5:], whole.pack_voltage_v[-5:], rtol=0, atol=1e-9)
    assert pack.soc_of(rest.final_state) == pytest.approx(pack.soc_of(whole.final_state), abs=1e-12)
    assert pack.soc_of(whole.final_state) < 0.5


def test_run_stops_at_the_cutoff_with_the_cutoff_voltage_last(ranger_params):
    pack = EnginePack(ranger_params, samples_per_segment=2)
    run = pack.run(0.1, [(600.0, 20.0)] * 6, 298.15)
    assert run.reached_cutoff
    assert run.time_s[-1] == pytest.approx(run.end_time_s)
    cell_v = (run.pack_voltage_v[-1] + 20.0 * pack.r_eq_ohm) / ranger_params.series
    assert cell_v == pytest.approx(pack.model.lower_cutoff_v, abs=1e-7)
    assert isinstance(run.final_state, EngineState)
    again = pack.run(run.final_state, [(60.0, 30.0)], 298.15)  # more current than the cut-off was reached at
    assert again.reached_cutoff and again.end_time_s == 0.0 and np.isnan(again.pack_voltage_v[0])


def test_refuses_an_soc_outside_the_model_and_an_uncovered_extension(ranger_params):
    with pytest.raises(SimulationError, match="SOC must be within"):
        EnginePack(ranger_params).run(1.9, [(60.0, 1.0)], 298.15)
    with pytest.raises(SimulationError, match="cell_imbalance"):
        EnginePack(ranger_params.with_values({}, extensions=("cell_imbalance",)))


def test_weak_group_matches_the_pybamm_pack_model(ranger_params, longest_route_segments):
    from battery_predictor.prediction.cell_runner import PackRunner
    from battery_predictor.simulation.extensions import group_socs, weak_group_fraction

    params = ranger_params.with_values({"Weak series group capacity fraction": 0.8}, extensions=("cell_imbalance",))
    pack = EnginePack(params, weak_fraction=weak_group_fraction(params))
    runner = PackRunner(params)
    engine, pybamm_run = pack.run(0.3, longest_route_segments, 298.15), runner.run(0.3, longest_route_segments, 298.15)
    np.testing.assert_allclose(engine.pack_voltage_v, pybamm_run.pack_voltage_v, rtol=0, atol=PACK_TOLERANCE_V)
    assert pack.capacity_ah == pytest.approx(runner.capacity_ah, rel=1e-6)
    # the same charge drawn from full leaves the normal cells at a higher SOC than the weak group's 0.3
    normal_soc = group_socs(0.3, 0.8)[0]
    assert normal_soc == pytest.approx(0.44)
    plain = EnginePack(ranger_params).run(normal_soc, longest_route_segments, 298.15)
    assert engine.pack_voltage_v[-1] < plain.pack_voltage_v[-1] - 0.003  # the weak group sags more
    low = pack.run(0.12, [(600.0, 20.0)] * 4, 298.15)
    low_pybamm = runner.run(0.12, [(600.0, 20.0)] * 4, 298.15)
    assert low.reached_cutoff and low_pybamm.reached_cutoff
    assert low.end_time_s == pytest.approx(low_pybamm.end_time_s, rel=1e-4)
    rest = pack.run(pack.run(0.3, longest_route_segments[:40], 298.15).final_state, longest_route_segments[40:], 298.15)
    np.testing.assert_allclose(rest.pack_voltage_v[-3:], engine.pack_voltage_v[-3:], rtol=0, atol=1e-9)


def test_temperature_extension_matches_the_pybamm_pack_model_in_the_cold(ranger_params, longest_route_segments):
    from battery_predictor.prediction.cell_runner import PackRunner
    from battery_predictor.simulation.extensions import EA_SERIES, extension_value

    params = ranger_params.with_values({"Negative particle diffusivity activation energy [J.mol-1]": 30000.0,
                                 "Positive particle diffusivity activation energy [J.mol-1]": 25000.0,
                                 EA_SERIES: 20000.0}, extensions=("temperature",))
    pack = EnginePack(params, series_activation_j_mol=extension_value(params, EA_SERIES))
    engine = pack.run(0.3, longest_route_segments, 278.15)
    pybamm_run = PackRunner(params).run(0.3, longest_route_segments, 278.15)
    np.testing.assert_allclose(engine.pack_voltage_v, pybamm_run.pack_voltage_v, rtol=0, atol=PACK_TOLERANCE_V)
    warm = pack.run(0.3, longest_route_segments, 298.15)
    assert engine.pack_voltage_v[-1] < warm.pack_voltage_v[-1] - 0.01
    with pytest.raises(SimulationError, match="series_activation_j_mol"):
        EnginePack(params)


def test_warm_up_compiles_the_route_kernel_and_the_sampled_run(ranger_params):
    pytest.importorskip("numba")
    from battery_predictor.simulation.engine.kernel import fused_kernel, voltage_kernels

    pack = EnginePack(ranger_params)
    pack.warm_up(298.15)
    kernels = voltage_kernels(pack.model)
    assert kernels is not None and fused_kernel(pack.model).signatures
    for compiled in (kernels.grid, kernels.cutoff_roots, kernels.surfaces_within):
        assert compiled.signatures  # compiled, so the first runtime update does not compile them
