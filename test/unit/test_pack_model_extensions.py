"""The predictor's pack model runs every extension the engine covers on the engine, and says when it cannot.

Issue 18: an extension runs in the engine with a stated error, or falls back to PyBaMM visibly. The
stated error here: the engine's pack (``pack_model``) within :data:`SAME_AS_PYBAMM_V` of the PyBaMM
stepping runner (``PackRunner``) on the longest Ranger route, at 263-310 K, same cut-off times.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import SimulationError
from battery_predictor.prediction.cell_runner import PackRunner
from battery_predictor.prediction.pack_model import FALLBACK_PREFIX, pack_model
from battery_predictor.simulation.engine.segments import EnginePack
from battery_predictor.simulation.extensions import (
    ANCHOR_TEMPERATURE,
    COLD_CHARGE_TRANSFER,
    COLD_RESISTANCE,
    COLD_WINDOW,
    CONTACT_RESISTANCE,
    CURRENT_OFFSET,
    EA_KINETICS,
    EA_NEG,
    EA_POS,
    EA_POS_FULL,
    EA_SERIES,
    HYS_HALF_WIDTH,
    WEAK_FRACTION,
)

REPO = Path(__file__).resolve().parents[2]
#: PackRunner steps PyBaMM at rtol 1e-6 / atol 1e-8; the engine is exact for the same discretised model.
SAME_AS_PYBAMM_V = 1e-4
#: Every extension the engine covers, at once, with values that move the voltage by tens of mV in the cold.
COVERED = {
    CURRENT_OFFSET: 0.3, CONTACT_RESISTANCE: 0.002, WEAK_FRACTION: 0.85,
    EA_NEG: 30000.0, EA_POS: 25000.0, EA_SERIES: 20000.0, EA_KINETICS: 20000.0, COLD_WINDOW: 0.004,
    COLD_RESISTANCE: 0.005, COLD_CHARGE_TRANSFER: 0.003, ANCHOR_TEMPERATURE: 300.0,
}
EXTENSIONS = ("current_offset", "resistance_growth", "cell_imbalance", "temperature")


@pytest.fixture(scope="module")
def covered(ranger_params):
    return ranger_params.with_values(COVERED, extensions=EXTENSIONS)


def test_every_covered_extension_runs_on_the_engine_within_the_stated_error(covered, longest_route_segments):
    engine, line = pack_model(covered)
    assert isinstance(engine, EnginePack)
    assert line.startswith("engine") and all(name in line for name in EXTENSIONS)
    runner = PackRunner(covered)
    plain = EnginePack(covered.with_values({}, extensions=()))
    for temperature_k in (263.15, 283.15, 310.0):
        ours, theirs = engine.run(0.6, longest_route_segments, temperature_k), runner.run(0.6, longest_route_segments, temperature_k)
        assert ours.reached_cutoff == theirs.reached_cutoff
        np.testing.assert_allclose(ours.pack_voltage_v, theirs.pack_voltage_v, rtol=0, atol=SAME_AS_PYBAMM_V)
        end = engine.run_end(0.6, longest_route_segments, temperature_k)
        assert end.pack_voltage_v == pytest.approx(theirs.pack_voltage_v[-1], abs=SAME_AS_PYBAMM_V)
    cold = engine.run(0.6, longest_route_segments, 263.15).pack_voltage_v[-1]
    assert cold < plain.run(0.6, longest_route_segments, 263.15).pack_voltage_v[-1] - 0.05  # the extensions act


def test_the_cut_off_in_the_cold_is_where_pybamm_finds_it(covered):
    engine, runner = pack_model(covered)[0], PackRunner(covered)
    segments = [(600.0, 20.0)] * 8
    ours, theirs = engine.run(0.5, segments, 268.15), runner.run(0.5, segments, 268.15)
    assert ours.reached_cutoff and theirs.reached_cutoff
    assert ours.end_time_s == pytest.approx(theirs.end_time_s, rel=2e-4)


def test_thermal_cells_run_on_the_engine(ranger_params):
    params = replace(ranger_params, options={"thermal": "lumped"})
    pack, line = pack_model(params)
    assert isinstance(pack, EnginePack) and line.startswith("engine")


def test_a_stoichiometry_dependent_diffusivity_falls_back_visibly(ranger_params):
    params = ranger_params.with_values({EA_POS_FULL: 20000.0}, extensions=("temperature",))
    runner, line = pack_model(params)
    assert isinstance(runner, PackRunner)
    assert line.startswith(FALLBACK_PREFIX) and "depends on the stoichiometry" in line
    with pytest.raises(SimulationError, match="depends on the stoichiometry"):
        pack_model(params, "engine")
    neutral = ranger_params.with_values({EA_POS_FULL: 0.0}, extensions=("temperature",))
    assert isinstance(pack_model(neutral)[0], EnginePack)


@pytest.mark.parametrize("values, extension", [({}, "electrolyte_transport"), ({HYS_HALF_WIDTH: 0.02}, "hysteresis")])
def test_an_uncovered_extension_falls_back_visibly(ranger_params, values, extension):
    runner, line = pack_model(ranger_params.with_values(values, extensions=(extension,)))
    assert isinstance(runner, PackRunner) and line.startswith(FALLBACK_PREFIX)


def test_the_engine_simulator_hands_a_stoichiometry_dependent_diffusivity_on_visibly(ranger_params, caplog):
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.engine.simulator import EngineSimulator

    params = ranger_params.with_values({EA_POS_FULL: 20000.0}, extensions=("temperature",))
    request = SimulationRequest(load=StepLoad.constant(10.0, 600.0), initial_soc=0.5, ambient_temperature_k=268.15)
    with caplog.at_level(logging.WARNING):
        result = EngineSimulator().simulate(params, request)
    assert "depends on the stoichiometry" in result.extra["engine_fallback"]
    assert "depends on the stoichiometry" in caplog.text
    # callers that ask before simulating (the diagnosis' reference fit) learn it as well
    assert "depends on the stoichiometry" in EngineSimulator.unsupported_reason(params, request)
    neutral = ranger_params.with_values({EA_POS_FULL: 0.0}, extensions=("temperature",))
    assert EngineSimulator.unsupported_reason(neutral, request) is None


def test_simulate_json_reports_the_engine_time_and_a_fallback(ranger_params, tmp_path, capsys):
    import json

    from battery_predictor.cli.main import main

    csv = tmp_path / "load.csv"
    csv.write_text("time_s,voltage_V,current_A\n" + "".join(
        f"{t:.1f},{50.0 - 0.002 * t:.4f},10.0\n" for t in range(0, 1200, 10)))
    cold = replace(ranger_params, operating={**ranger_params.operating, "ambient_temperature_k": 268.15}, extensions=("temperature",))
    covered = replace(cold, extra={COLD_WINDOW: 0.004}).to_yaml(tmp_path / "covered.yaml")
    uncovered = replace(cold, extra={EA_POS_FULL: 20000.0}).to_yaml(tmp_path / "uncovered.yaml")
    outs = {}
    for name, path in (("covered", covered), ("uncovered", uncovered)):
        assert main(["simulate", "--params", str(path), "--data", str(csv), "--json"]) == 0
        outs[name] = json.loads(capsys.readouterr().out)
    assert outs["covered"]["engine_fallback"] is None and 0 < outs["covered"]["engine_seconds"] < 60
    assert "depends on the stoichiometry" in outs["uncovered"]["engine_fallback"]
    assert outs["uncovered"]["engine_seconds"] is None
