"""The emulation lab's real pack (liionpack, per-cell spread) against the fast simulator and its stop voltage (solver-heavy)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from battery_predictor.lab.real_pack import (
    RealPack,
    RealPackSpec,
)
from battery_predictor.simulation import SimulationRequest, StepLoad
from battery_predictor.simulation.fast import FastPackSimulator


def test_real_pack_without_spread_matches_the_fast_simulator(temi_params):
    """Guards the liionpack input-order workaround: swapped inputs would be grossly off."""
    spec = RealPackSpec("p", seed=1, capacity_sigma=0.0, contact_resistance_sigma_ohm=0.0, heat_transfer_sigma=0.0,
                        contact_resistance_mean_ohm=0.01)
    pack = RealPack(dataclasses.replace(temi_params, series=1, parallel=2), spec)
    load = StepLoad.from_durations([300.0, 300.0], [2.0, 4.0])
    trace = pack.simulate(load, period_s=5.0)
    assert trace.termination == "end_of_load" and len(trace.time_s) == 120
    fast = FastPackSimulator().simulate(pack.mean_params(), SimulationRequest(load=load, output_time_s=trace.time_s))
    diff = np.abs(fast.pack_voltage_v - trace.voltage_v)
    diff[60] = 0.0  # liionpack's Thevenin step at the current edge (Ri of the previous step)
    assert np.max(diff) < 0.005
    # the contact resistance is really in: 10 mOhm per cell, 2 cells in parallel
    no_contact = FastPackSimulator().simulate(
        pack.mean_params().with_values({"Contact resistance [Ohm]": 0.0}),
        SimulationRequest(load=load, output_time_s=trace.time_s))
    drop = no_contact.pack_voltage_v - trace.voltage_v
    assert 0.005 * 2.0 * 0.5 < np.median(drop[:60]) < 0.01 * 2.0
    # the lumped thermal model warms the cells
    assert trace.temperature_k[-1] > trace.ambient_temperature_k + 0.05


def test_real_pack_spread_and_stop_voltage(temi_params):
    spec = RealPackSpec("p", seed=4, capacity_sigma=0.05, contact_resistance_sigma_ohm=0.004)
    pack = RealPack(dataclasses.replace(temi_params, series=1, parallel=2), spec)
    load = StepLoad.constant(6.0, 3600.0)
    full = pack.simulate(load, period_s=10.0)
    stop_v = 0.5 * float(full.voltage_v[30] + full.voltage_v[31])  # liionpack stores float32
    trace = pack.simulate(load, stop_pack_voltage_v=stop_v, stop_extra_steps=2, period_s=10.0)
    assert trace.termination == "pack_voltage"
    assert trace.time_to_voltage_s(stop_v) == pytest.approx(trace.time_s[-2])
    assert np.all(trace.voltage_v[:-2] > stop_v)
    np.testing.assert_allclose(trace.voltage_v, full.voltage_v[: len(trace.voltage_v)])
    # different cells carry different currents
    assert np.ptp(trace.extra["cell_current_a"][5]) > 0.01
