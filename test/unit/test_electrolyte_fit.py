"""The ``electrolyte_transport`` extension (SPMe) in the identification: its Bruggeman coordinate and one built model."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.simulation import extensions as ext
from battery_predictor.simulation.base import SimulationRequest
from battery_predictor.simulation.load import StepLoad

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def panasonic_spme():
    params = load_params(REPO / "params" / "panasonic_18650pf.yaml")
    return replace(params, extensions=(*params.extensions, "electrolyte_transport"))


def test_the_bruggeman_exponent_is_a_coordinate_of_the_extension_and_lands_in_cell_extra(panasonic_spme):
    from battery_predictor.fitting.identifiable import ELECTROLYTE_BRUGGEMAN_RANGE, default_space, pybamm_values

    space = {c.name: c for c in default_space(panasonic_spme)}
    brug = space["electrolyte_bruggeman"]
    assert (brug.initial, brug.low, brug.high, brug.log) == (1.5, *ELECTROLYTE_BRUGGEMAN_RANGE, False)
    assert "electrolyte_bruggeman" not in {c.name for c in default_space(replace(panasonic_spme, extensions=()))}
    ready = ext.with_fitted_extension_keys(panasonic_spme)
    assert ready.extra[ext.BRUGGEMAN] == 1.5
    fitted = ready.with_values(pybamm_values(ready, {"electrolyte_bruggeman": 2.7})[0])
    assert fitted.extra[ext.BRUGGEMAN] == 2.7 and ext.BRUGGEMAN not in fitted.fitted
    pv = ext.apply_extension_parameter_values(fitted, fitted.parameter_values())
    assert all(pv[key] == 2.7 for key in ext.BRUGGEMAN_KEYS)


def test_the_fast_simulator_solves_another_bruggeman_exponent_on_the_built_spme(panasonic_spme):
    from battery_predictor.simulation.fast import FastPackSimulator

    sim = FastPackSimulator()
    request = SimulationRequest(load=StepLoad(np.array([0.0, 300.0]), np.array([0.7, 10.7]), 330.0))
    ready = ext.with_fitted_extension_keys(panasonic_spme)
    low = sim.simulate(ready, request)
    high = sim.simulate(ready.with_values({ext.BRUGGEMAN: 3.0}), request)
    assert sim.builds == 1
    # a larger exponent (a more tortuous electrolyte) drops more voltage under the 10.7 A step
    assert high.pack_voltage_v[-1] < low.pack_voltage_v[-1] - 0.01
    fresh = FastPackSimulator().simulate(ready.with_values({ext.BRUGGEMAN: 3.0}), request)
    np.testing.assert_allclose(high.pack_voltage_v, fresh.pack_voltage_v, atol=1e-6)
