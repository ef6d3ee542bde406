"""The ``temperature`` extension's physics: Arrhenius kinetics, a capacity that falls in the cold, nothing at T_ref."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.diagnosis.diagnose import rest_soc_box
from battery_predictor.diagnosis.engine import Engine, observe
from battery_predictor.diagnosis.reference import reference_anchor_k
from battery_predictor.params import load_params
from battery_predictor.recording import Recording
from battery_predictor.simulation import extensions as ext

PARAMS = Path(__file__).resolve().parents[2] / "params"


def _lgm50(**extra):
    params = load_params(PARAMS / "lgm50.yaml")
    return replace(params, extensions=("temperature",), extra={**dict(params.extra), **extra})


def test_lithiation_weight_acts_only_towards_full_lithiation():
    w = ext.lithiation_weight(np.array([0.0, 0.5, 0.75, 1.0]))
    assert w.tolist() == pytest.approx([0.0, 0.0, 0.25, 1.0])


def test_exchange_current_gets_the_extra_arrhenius_factor_and_none_at_the_reference_temperature():
    import pybamm

    from battery_predictor.simulation.cell_setup import prepared_parameter_values

    ea = 30000.0
    plain = load_params(PARAMS / "lgm50.yaml").parameter_values()
    pv = prepared_parameter_values(_lgm50(**{ext.EA_KINETICS: ea}))
    key = "Negative electrode exchange-current density [A.m-2]"
    args = (pybamm.Scalar(1000.0), pybamm.Scalar(15000.0), pybamm.Scalar(33133.0))

    def value(values, temperature_k):
        sym = values[key](*args, pybamm.Scalar(temperature_k))
        return float(values.process_symbol(sym).evaluate())

    assert value(pv, 298.15) == pytest.approx(value(plain, 298.15), rel=1e-9)
    ratio = value(pv, 273.15) / value(plain, 273.15)
    assert ratio == pytest.approx(math.exp(-ea / ext.R_GAS * (1 / 273.15 - 1 / 298.15)), rel=1e-9)


@pytest.mark.slow
def test_full_lithiation_activation_shortens_a_cold_discharge_only():
    """Accessible capacity with a physical basis: the cold 1C discharge ends earlier, the 25 degC one does not move."""
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.fast import FastPackSimulator

    load = StepLoad.constant(5.0, 4000.0)
    ends = {}
    for ea_full in (0.0, 100000.0):
        params = _lgm50(**{ext.EA_NEG: 20000.0, ext.EA_POS: 20000.0, ext.EA_POS_FULL: ea_full})
        for t_k in (298.15, 273.15):
            res = FastPackSimulator().simulate(params, SimulationRequest(load=load, ambient_temperature_k=t_k))
            ends[(ea_full, t_k)] = res.end_time_s
    assert ends[(100000.0, 298.15)] == pytest.approx(ends[(0.0, 298.15)], rel=2e-3)
    assert ends[(100000.0, 273.15)] < 0.97 * ends[(0.0, 273.15)]


def test_rest_soc_box_narrows_the_start_of_a_recording_that_starts_at_rest():
    params = load_params(PARAMS / "lgm50.yaml")
    t = np.arange(0.0, 600.0, 10.0)
    v = np.linspace(3.9, 3.7, t.size)
    at_rest = observe(Recording(t, v, np.where(t > 0, 5.0, 0.0), None), params)
    loaded = observe(Recording(t, v, np.full(t.size, 5.0), None), params)
    lo, hi = rest_soc_box(Engine(), params, at_rest, tol_v=0.02)
    assert 0.0 < lo < hi < 1.0 and hi - lo < 0.3
    assert rest_soc_box(Engine(), params, loaded, tol_v=0.02) == (0.0, 1.0)


def test_arrhenius_cell_resistance_adds_only_its_excess_over_the_reference_temperature():
    r_ref = 0.01
    assert float(ext.cold_resistance_excess_ohm(r_ref, 298.15)) == pytest.approx(0.0, abs=1e-15)
    cold = float(ext.cold_resistance_excess_ohm(r_ref, 273.15))
    expected = r_ref * (math.exp(ext.COLD_RESISTANCE_ACTIVATION_J_MOL / ext.R_GAS * (1 / 273.15 - 1 / 298.15)) - 1)
    assert cold == pytest.approx(expected) and 0.015 < cold < 0.025  # about 2x the 298.15 K value at 0 degC
    # the predictor's runner carries it through the pack's series resistance factor
    temi = load_params(PARAMS / "temi.yaml")
    params = replace(temi, extensions=("temperature",), extra={**dict(temi.extra), ext.COLD_RESISTANCE: r_ref})
    assert float(ext.series_resistance_factor(params, 298.15)) == pytest.approx(1.0)
    assert float(ext.series_resistance_factor(params, 273.15)) > 1.0


def test_cold_window_scale_narrows_below_the_reference_temperature_and_widens_above():
    assert float(ext.cold_window_scale(0.004, ext.COLD_REFERENCE_K)) == pytest.approx(1.0)
    assert float(ext.cold_window_scale(0.004, 273.15)) == pytest.approx(1.0 / (1.0 - 0.004 * 25.0))
    assert float(ext.cold_window_scale(0.004, 318.15)) == pytest.approx(1.0 / (1.0 + 0.004 * 20.0))
    assert float(ext.cold_window_scale(0.0, 253.15)) == pytest.approx(1.0)


def test_window_and_cell_resistance_change_nothing_at_the_anchor_temperature():
    anchor_k = 309.55
    assert float(ext.cold_window_scale(0.004, anchor_k, anchor_k)) == pytest.approx(1.0)
    assert float(ext.cold_window_scale(0.004, 298.15, anchor_k)) == pytest.approx(1.0 / (1.0 - 0.004 * 11.4))
    assert float(ext.cold_resistance_excess_ohm(0.01, anchor_k, anchor_k)) == pytest.approx(0.0, abs=1e-15)
    assert float(ext.cold_resistance_excess_ohm(0.01, 298.15, anchor_k)) > 0.0  # below the anchor: more resistance
    temi = load_params(PARAMS / "temi.yaml")
    params = replace(temi, extensions=("temperature",),
                     extra={**dict(temi.extra), ext.COLD_RESISTANCE: 0.01, ext.ANCHOR_TEMPERATURE: anchor_k})
    assert float(ext.series_resistance_factor(params, anchor_k)) == pytest.approx(1.0)
    assert float(ext.series_resistance_factor(params, 298.15)) > 1.0


def test_reference_anchor_is_the_mean_temperature_where_the_reference_discharges_end():
    t = np.arange(0.0, 100.0)
    rest_after = np.where(t < 80, 5.0, 0.0)  # discharges until t = 79, then rests (and cools)
    warm = np.where(t < 80, 298.15 + 0.4 * t, 300.0)  # self-heats to 329.75 K at the end of the discharge
    cool = np.full(t.size, 298.15)
    anchor_k = reference_anchor_k([warm, cool], [rest_after, np.full(t.size, 1.0)])
    assert anchor_k == pytest.approx(0.5 * (298.15 + 0.4 * 79 + 298.15))


def test_diagnosis_anchors_the_temperature_extension_at_measured_references_only():
    from battery_predictor.diagnosis.diagnose import with_reference_anchor

    params = load_params(PARAMS / "lgm50.yaml")
    t = np.arange(0.0, 600.0, 10.0)
    v = np.linspace(4.1, 3.0, t.size)
    measured = observe(Recording(t, v, np.full(t.size, 5.0), np.linspace(298.15, 318.15, t.size)), params)
    unmeasured = observe(Recording(t, v, np.full(t.size, 5.0), None), params)
    anchored = with_reference_anchor(params, [measured])
    assert ext.extension_value(anchored, ext.ANCHOR_TEMPERATURE) == pytest.approx(318.15)
    assert with_reference_anchor(params, [measured, unmeasured]) is params
    assert ext.extension_value(params, ext.ANCHOR_TEMPERATURE) == ext.COLD_REFERENCE_K


@pytest.mark.slow
def test_cold_window_shortens_a_cold_low_rate_discharge_and_changes_nothing_at_the_reference_temperature():
    """Accessible capacity at any rate: a 0.5C discharge at 0 degC ends ~loss x 25 K earlier, at 25 degC it does not move."""
    from battery_predictor.diagnosis.candidates import Temperature

    params = load_params(PARAMS / "lgm50.yaml")
    t = np.arange(0.0, 8000.0, 20.0)
    ends = {}
    for temp_k in (298.15, 273.15):
        rec = Recording(t, np.linspace(4.1, 3.3, t.size), np.full(t.size, 2.5), np.full(t.size, temp_k))
        obs = observe(rec, params)
        for loss in (0.0, 0.004):
            theta = {"diffusivity_activation_energy_J_mol": 0.0, "charge_transfer_resistance_ohm": 1e-5, "window_loss_per_k": loss}
            ends[(temp_k, loss)] = Temperature().simulate(Engine(), params, obs, theta, 1.0).end_time_s
    assert ends[(298.15, 0.004)] == pytest.approx(ends[(298.15, 0.0)], rel=2e-3)
    assert ends[(273.15, 0.004)] < 0.95 * ends[(273.15, 0.0)]


def test_charge_transfer_excess_is_zero_at_the_anchor_and_grows_in_the_cold_towards_the_empty_negative():
    r_ohm, anchor_k = 0.01, 301.5
    assert float(ext.charge_transfer_excess_ohm(r_ohm, 0.5, anchor_k, anchor_k)) == pytest.approx(0.0, abs=1e-15)
    arrhenius = math.exp(ext.COLD_RESISTANCE_ACTIVATION_J_MOL / ext.R_GAS * (1 / 273.15 - 1 / anchor_k))
    half = float(ext.charge_transfer_excess_ohm(r_ohm, 0.5, 273.15, anchor_k))
    assert half == pytest.approx(r_ohm * (arrhenius - 1.0))  # the stated value at half lithiation
    empty = float(ext.charge_transfer_excess_ohm(r_ohm, 0.06, 273.15, anchor_k))
    assert empty == pytest.approx(half * 0.5 / math.sqrt(0.06 * 0.94))  # 1 / j0 ~ 1 / sqrt(x (1 - x))
    assert float(ext.charge_transfer_excess_ohm(r_ohm, 0.5, 310.0, anchor_k)) < 0.0  # warmer than the anchor


def test_charge_transfer_excess_follows_the_stoichiometry_the_cold_window_moves():
    r_ohm, x_charged, loss = 0.01, 0.8, 0.004
    plain = float(ext.charge_transfer_excess_ohm(r_ohm, 0.2, 273.15, 298.15))
    moved = float(ext.charge_transfer_excess_ohm(r_ohm, 0.2, 273.15, 298.15, loss, x_charged))
    x_moved = x_charged + (0.2 - x_charged) / (1.0 - loss * 25.0)
    assert moved == pytest.approx(plain * float(ext.charge_transfer_shape(x_moved) / ext.charge_transfer_shape(0.2)))
    assert moved > plain


@pytest.mark.slow
def test_charge_transfer_term_drops_the_cold_voltage_by_current_times_its_excess_and_nothing_at_the_anchor():
    """In PyBaMM's model: V - I R_excess(x_surf, T); at the anchor temperature the voltage is the model's own."""
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.fast import FastPackSimulator

    base = load_params(PARAMS / "lgm50.yaml")
    cell_a = 5.0
    load = StepLoad.constant(cell_a * base.parallel, 120.0)
    volts = {}
    for r_ohm in (0.0, 0.01):
        params = _lgm50(**{ext.COLD_CHARGE_TRANSFER: r_ohm})
        for t_k in (298.15, 273.15):
            res = FastPackSimulator().simulate(params, SimulationRequest(load=load, ambient_temperature_k=t_k))
            volts[(r_ohm, t_k)] = np.asarray(res.pack_voltage_v) / base.series
    np.testing.assert_allclose(volts[(0.01, 298.15)], volts[(0.0, 298.15)], rtol=0, atol=1e-6)
    drop = volts[(0.0, 273.15)] - volts[(0.01, 273.15)]
    lowest = float(ext.charge_transfer_excess_ohm(0.01, 0.5, 273.15))  # the shape is smallest at half lithiation
    assert np.all(drop >= cell_a * lowest)
    x_charged = ext.cold_window_anchors(base)[0]  # the full cell's negative surface at the start
    assert drop[0] == pytest.approx(cell_a * float(ext.charge_transfer_excess_ohm(0.01, x_charged, 273.15)), rel=0.05)
