"""A pack that stops on its weakest series group: the fit searches the group's capacity fraction.

Measured packs end when one group reaches the cell cut-off (the Nissan Leaf 6S2P data in
``../shared/data``: group 1 at 3.0 V while the pack reads 19.4-20.2 V, not 18 V); with the
``cell_imbalance`` extension the identification has a coordinate for it, written to ``cell.extra``.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from battery_predictor.fitting.identifiable import (
    WEAK_GROUP_FRACTION_RANGE,
    default_space,
    pybamm_values,
    shipped_coordinates,
)
from battery_predictor.fitting.identification import IdentificationProblem, identify
from battery_predictor.recording import Recording
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator
from battery_predictor.simulation.extensions import WEAK_FRACTION, weak_group_fraction, with_fitted_extension_keys


@pytest.fixture(scope="module")
def imbalanced(temi_params):
    return dataclasses.replace(temi_params, extensions=("cell_imbalance",))


def test_the_weak_group_fraction_is_searched_only_with_the_extension(temi_params, imbalanced):
    assert "weak_group_capacity_fraction" not in {c.name for c in default_space(temi_params)}
    coord = {c.name: c for c in default_space(imbalanced)}["weak_group_capacity_fraction"]
    assert (coord.low, coord.high) == WEAK_GROUP_FRACTION_RANGE and not coord.log
    assert coord.initial == 1.0  # the extension's neutral default: no weak group


def test_a_fitted_weak_fraction_reaches_the_extension_value_in_cell_extra(imbalanced):
    values = pybamm_values(imbalanced, {**shipped_coordinates(imbalanced), "weak_group_capacity_fraction": 0.83})[0]
    fitted = with_fitted_extension_keys(imbalanced).with_values(values)
    assert fitted.extra[WEAK_FRACTION] == pytest.approx(0.83)
    assert WEAK_FRACTION not in fitted.fitted
    assert weak_group_fraction(fitted) == pytest.approx(0.83)


def test_refinement_near_the_truth_finds_the_weak_group_from_where_the_pack_stops(imbalanced):
    truth = {**shipped_coordinates(imbalanced), "weak_group_capacity_fraction": 0.85}
    truth_params = with_fitted_extension_keys(imbalanced).with_values(pybamm_values(imbalanced, truth)[0])
    assert weak_group_fraction(truth_params) == pytest.approx(0.85)
    rng = np.random.default_rng(7)
    load = StepLoad.from_durations(np.r_[60.0, rng.uniform(120.0, 300.0, 60)], np.r_[0.0, rng.uniform(5.0, 25.0, 60)])
    sim = get_simulator("engine")
    res = sim.simulate(truth_params, SimulationRequest(load=load, output_time_s=np.arange(0.0, load.end_s, 10.0)))
    assert res.termination == "cell_cutoff"
    rec = Recording(res.time_s, res.pack_voltage_v + rng.normal(0.0, 0.004, res.time_s.size),
                    load.current_at(res.time_s), source="synthetic weak group")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        space = default_space(imbalanced, [rec])
    near = {name: value * 1.03 for name, value in truth.items()}
    near["weak_group_capacity_fraction"] = 0.92
    space = [dataclasses.replace(c, initial=near[c.name]) if c.name in near else c for c in space]
    problem = IdentificationProblem(with_fitted_extension_keys(imbalanced), [rec], sim, space)
    result = identify(problem, evaluations=120, seed=0, tpe_fraction=0.0, starts=1)
    assert result.coordinates["weak_group_capacity_fraction"] == pytest.approx(0.85, abs=0.02)
