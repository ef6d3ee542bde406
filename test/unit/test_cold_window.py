"""The cold stoichiometry window (extension ``temperature``): its anchors and a deterministic engine.

The window narrows each electrode's stoichiometry towards its charged end. That end is the electrode
balance PyBaMM's ``get_min_max_stoichiometries`` solves, computed here on the OCP tables; the engine
bakes it into its extraction, so a candidate's voltage must not depend on the candidates simulated
before it (it did: a fit's result depended on the order of its trials).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pybamm
import pytest

from battery_predictor.params import load_params
from battery_predictor.simulation.base import SimulationRequest
from battery_predictor.simulation.engine.simulator import EngineSimulator
from battery_predictor.simulation.extensions import (
    COLD_ANCHOR_KEYS,
    cold_window_anchors,
    with_cold_window_anchors,
)
from battery_predictor.simulation.load import StepLoad

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def panasonic():
    return load_params(REPO / "params" / "panasonic_18650pf.yaml")


@pytest.mark.parametrize("name", ["params/panasonic_18650pf.yaml", "params/temi.yaml",
                                  "docs/runtime_real_data/panasonic_ocv_fit.yaml"])
def test_the_anchors_are_the_charged_end_pybamm_solves(name):
    params = load_params(REPO / name)
    pv = params.parameter_values()
    _, x100, y100, _ = pybamm.lithium_ion.get_min_max_stoichiometries(pv)
    anchors = cold_window_anchors(params, pv)
    assert anchors == pytest.approx((x100, y100), abs=1e-4)


def test_fixed_anchors_are_kept_in_cell_extra_and_used(panasonic, tmp_path):
    fixed = with_cold_window_anchors(panasonic)
    assert set(COLD_ANCHOR_KEYS) <= set(fixed.extra)
    fixed.to_yaml(tmp_path / "fixed.yaml")
    assert cold_window_anchors(load_params(tmp_path / "fixed.yaml")) == cold_window_anchors(fixed)
    moved = fixed.with_values({"Negative electrode thickness [m]": 1.3 * float(
        fixed.parameter_values()["Negative electrode thickness [m]"])})
    assert cold_window_anchors(moved) == cold_window_anchors(fixed)
    assert cold_window_anchors(replace(moved, extra=panasonic.extra)) != cold_window_anchors(fixed)
    neutral = replace(panasonic, extensions=())
    assert with_cold_window_anchors(neutral) is neutral


def _voltage(sim: EngineSimulator, params, thickness_factor: float) -> np.ndarray:
    key = "Negative electrode thickness [m]"
    cell = params.with_values({key: thickness_factor * float(params.parameter_values()[key])})
    load = StepLoad(np.array([0.0, 600.0]), np.array([2.0, 4.0]), 1800.0)
    req = SimulationRequest(load=load, ambient_temperature_k=268.15)
    return sim.simulate(cell, req).pack_voltage_v


def test_a_candidates_voltage_does_not_depend_on_the_candidates_before_it(panasonic):
    first, second = EngineSimulator(), EngineSimulator()
    _voltage(first, panasonic, 1.4)
    after_other = _voltage(first, panasonic, 1.0)
    alone = _voltage(second, panasonic, 1.0)
    assert np.array_equal(after_other, alone)
