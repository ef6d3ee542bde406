"""The predictor's runner with the ``cell_imbalance`` extension: a weak series group limits the pack."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.prediction.calibration import Calibration, calibrate_on_history, calibrate_soc
from battery_predictor.prediction.cell_runner import PackRunner
from battery_predictor.prediction.runtime import predict_remaining_runtime
from battery_predictor.simulation import SimulationRequest, StepLoad
from battery_predictor.simulation import extensions as ext
from battery_predictor.simulation.fast import FastPackSimulator

PARAMS = Path(__file__).resolve().parents[2] / "params"
WEAK_FRACTION = 0.8


@pytest.fixture(scope="module")
def temi():
    return load_params(PARAMS / "temi.yaml")


@pytest.fixture(scope="module")
def weak_params(temi):
    return replace(temi, extensions=("cell_imbalance",), extra={ext.WEAK_FRACTION: WEAK_FRACTION})


@pytest.fixture(scope="module")
def runners(temi, weak_params):
    """(plain runner, runner with a weak group)."""
    return PackRunner(temi), PackRunner(weak_params)


def test_weak_group_shortens_the_runtime_by_about_its_capacity_fraction(runners):
    plain, weak = runners
    assert weak.capacity_ah == pytest.approx(WEAK_FRACTION * plain.capacity_ah, rel=1e-9)
    # same stoichiometries, less area; the normal groups stand higher, so the pack's top is lower
    assert weak.soc_bounds == pytest.approx(ext.pack_soc_bounds(plain.soc_bounds, WEAK_FRACTION))
    cal = Calibration(soc=0.9, residual_v=0.0)
    # a pack cut-off below series x the cell cut-off: the first cell at its cut-off ends the run
    kwargs = dict(voltage_v=15.5, current_a=3.0, temperature_k=298.15, average_current_a=3.0,
                  cutoff_voltage_v=10.0, calibration=cal)
    runtime_plain = predict_remaining_runtime(plain, **kwargs)
    runtime_weak = predict_remaining_runtime(weak, **kwargs)
    assert runtime_plain.limited_by == runtime_weak.limited_by == "cell_cutoff"
    assert runtime_weak.cell_limited and runtime_plain.cell_limited
    assert runtime_weak.remaining_s / runtime_plain.remaining_s == pytest.approx(WEAK_FRACTION, abs=0.03)
    # at the robot's pack cut-off the weak group's knee still ends the run earlier
    at_13v3 = {**kwargs, "cutoff_voltage_v": 13.30}
    ratio = (predict_remaining_runtime(weak, **at_13v3).remaining_s
             / predict_remaining_runtime(plain, **at_13v3).remaining_s)
    assert WEAK_FRACTION - 0.03 < ratio < 0.97
    assert not predict_remaining_runtime(plain, **at_13v3).cell_limited  # the pack threshold ends that run


def test_weak_group_runtime_matches_the_fast_simulator(weak_params, runners):
    _, weak = runners
    res = FastPackSimulator().simulate(weak_params, SimulationRequest(load=StepLoad.constant(7.0, 4 * 3600.0),
                                                                      initial_soc=0.9))
    assert res.termination == "cell_cutoff"
    run = weak.run(0.9, [(4 * 3600.0, 7.0)], 298.15)
    assert run.reached_cutoff
    assert run.end_time_s == pytest.approx(res.end_time_s, rel=2e-3)


def test_continued_state_carries_both_groups(runners):
    _, weak = runners
    segs = [(600.0, 3.0), (300.0, 9.0), (900.0, 1.5)]
    whole = weak.run(0.7, segs, 298.15)
    first = weak.run(0.7, segs[:2], 298.15)
    assert first.final_state.weak_solution is not None
    rest = weak.run(first.final_state, segs[2:], 298.15)
    assert rest.pack_voltage_v[-1] == pytest.approx(whole.pack_voltage_v[-1], abs=1e-6)
    # the reported SOC is the limiting (weak) group's: it falls by charge / usable capacity
    charge_ah = sum(d * i for d, i in segs) / 3600.0
    assert weak.soc_of(rest.final_state) == pytest.approx(0.7 - charge_ah / weak.capacity_ah)
    stripped = replace(first.final_state, weak_solution=None)
    with pytest.raises(Exception, match="weak-group"):
        weak.run(stripped, segs[2:], 298.15)


def test_calibrations_keep_the_weak_group_and_predict_the_simulated_runtime(weak_params, runners):
    _, weak = runners
    # truth: constant 2.5 A from full (both groups) until 13.30 V; the history covers 10 min from 2 h on, when
    # the weak group is further down than the normal ones (the predictor's groups were full together too)
    res = FastPackSimulator().simulate(weak_params, SimulationRequest(load=StepLoad.constant(2.5, 10 * 3600.0),
                                                                      initial_soc=1.0))
    t_true_s = res.time_to_pack_voltage_s(13.30)
    t_now_s = 7800.0
    t_hist = np.arange(t_now_s - 600.0, t_now_s + 1.0, 5.0)
    v_hist = np.interp(t_hist + 0.002, res.time_s, res.pack_voltage_v)
    hist = calibrate_on_history(weak, t_hist, v_hist, np.full(t_hist.size, 2.5), 298.15)
    assert hist.state is not None and hist.state.weak_solution is not None
    # the history starts under load, its particles not relaxed: a few tenths of a per cent
    assert hist.soc == pytest.approx(1.0 - 2.5 * t_now_s / 3600.0 / weak.capacity_ah, abs=4e-3)
    pred = predict_remaining_runtime(weak, float(v_hist[-1]), 2.5, 298.15, 2.5, 13.30, calibration=hist)
    assert pred.remaining_s == pytest.approx(t_true_s - t_now_s, rel=0.01)
    single = calibrate_soc(weak, float(v_hist[-1]), 2.5, 298.15)
    assert single.state is not None and single.state.weak_solution is not None
    from_state = predict_remaining_runtime(weak, float(v_hist[-1]), 2.5, 298.15, 2.5, 13.30, calibration=single)
    # the single sample assumes relaxed particles: about -2.5 %, as much as on the plain pack
    assert from_state.remaining_s == pytest.approx(t_true_s - t_now_s, rel=0.04)


def test_the_core_runs_covered_extensions_on_the_engine_and_says_when_it_cannot(weak_params):
    from battery_predictor.prediction.core import PredictorConfig, PredictorCore
    from battery_predictor.simulation.extensions import EA_POS_FULL

    weak = PredictorCore(PredictorConfig(params_file=str(weak_params.source)), params=weak_params)
    assert weak.model_backend.startswith("engine") and "cell_imbalance" in weak.model_backend
    uncovered = weak_params.with_values({EA_POS_FULL: 20000.0}, extensions=("cell_imbalance", "temperature"))
    pybamm = PredictorCore(PredictorConfig(params_file=str(weak_params.source)), params=uncovered)
    assert pybamm.model_backend.startswith("pybamm (the engine cannot run these params: ")
    assert isinstance(pybamm.runner, PackRunner)
    plain = PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml")))
    assert plain.model_backend.startswith("engine")
    forced = PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml"), simulator="pybamm"))
    assert forced.model_backend.startswith("pybamm")


@pytest.mark.parametrize(("soc", "fraction", "expected"), [
    (1.0, 0.8, (1.0, 1.0)),  # full: every group full
    (0.3, 0.8, (0.44, 0.3)),  # 0.7 x 0.8 of a normal group drawn: the normal groups at 0.44, the weak one at 0.3
    (0.5, 2.0, (0.5, 0.75)),  # a stronger group: the normal groups limit the pack
    (0.4, 1.0, (0.4, 0.4)),
    (1.05, 0.8, (1.04, 1.05)),  # above the 100 % OCV: by the same charge
])
def test_group_socs_are_what_the_same_charge_drawn_from_full_leaves_in_each_group(soc, fraction, expected):
    assert ext.group_socs(soc, fraction) == pytest.approx(expected)


@pytest.mark.parametrize("backend", ["engine", "pybamm"])
def test_a_run_from_an_soc_starts_where_a_discharge_from_full_to_that_soc_ends(weak_params, backend):
    from battery_predictor.prediction.pack_model import pack_model

    runner = pack_model(weak_params, backend)[0] if backend == "engine" else PackRunner(weak_params)
    drawn = runner.run(1.0, [(3 * 3600.0, 2.5), (4 * 3600.0, 0.0)], 298.15)  # then relaxed
    soc = runner.soc_of(drawn.final_state)
    assert 0.2 < soc < 0.8
    again = runner.run(soc, [(60.0, 0.0)], 298.15)
    assert again.pack_voltage_v[-1] == pytest.approx(drawn.pack_voltage_v[-1], abs=2e-3)
    loaded = (runner.run(soc, [(1800.0, 5.0)], 298.15), runner.run(drawn.final_state, [(1800.0, 5.0)], 298.15))
    assert loaded[0].pack_voltage_v[-1] == pytest.approx(loaded[1].pack_voltage_v[-1], abs=5e-3)


def test_the_packs_soc_range_keeps_every_group_inside_the_cells_range():
    low, high = ext.pack_soc_bounds((-0.4, 0.957), 0.75)
    assert (low, high) == pytest.approx((-0.4, 1.0 - 0.043 / 0.75))
    for soc in (low, high):
        assert all(-0.4 - 1e-12 <= g <= 0.957 + 1e-12 for g in ext.group_socs(soc, 0.75))
    assert ext.pack_soc_bounds((-0.4, 1.2), 0.75) == pytest.approx((-0.4, 1.2))  # above 1 the weak group binds
    assert ext.pack_soc_bounds((-0.4, 0.957), 1.0) == (-0.4, 0.957)


@pytest.mark.parametrize("backend", ["engine", "pybamm"])
def test_a_weak_pack_whose_cells_top_out_below_100_percent_calibrates_at_the_top_of_its_range(backend):
    from battery_predictor.prediction.pack_model import pack_model

    ranger = load_params(PARAMS / "ranger_mini.yaml").with_values({"Open-circuit voltage at 100% SOC [V]": 3.5})
    cell_top = pack_model(ranger)[0].soc_bounds[1]
    assert cell_top < 0.96  # the cells' stoichiometry range ends below the 100 % point
    weak = ext.with_weak_group(ranger, 0.75)
    runner = pack_model(weak, backend)[0] if backend == "engine" else PackRunner(weak)
    top = runner.soc_bounds[1]
    assert top == pytest.approx(1.0 - (1.0 - cell_top) / 0.75)  # the normal groups reach the cells' top there
    full = runner.run(top, [(60.0, 0.0)], 298.15)
    cal = calibrate_soc(runner, float(full.pack_voltage_v[-1]) + 0.5, 0.0, 298.15)  # above the model's top
    assert cal.soc == pytest.approx(top, abs=1e-6)
    assert math.isfinite(runner.run(cal.soc, [(600.0, 10.0)], 298.15).pack_voltage_v[-1])
