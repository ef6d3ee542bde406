"""The ``hysteresis`` extension: its exact step, its bounds, its direction, and the engine against PyBaMM's Axen model."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import SimulationError
from battery_predictor.params import load_params
from battery_predictor.simulation import extensions as ext
from battery_predictor.simulation.base import SimulationRequest
from battery_predictor.simulation.load import StepLoad

REPO = Path(__file__).resolve().parents[2]


def _fine(h0: float, current_a: float, duration_s: float, rate: float, n: int = 20000) -> float:
    """dh/dt = rate |I| (s - h) by classical Runge-Kutta on ``n`` sub-steps."""
    s = -np.sign(current_a)

    def f(h):
        return rate * abs(current_a) * (s - h)

    h, dt = h0, duration_s / n
    for _ in range(n):
        k1 = f(h)
        k2 = f(h + 0.5 * dt * k1)
        k3 = f(h + 0.5 * dt * k2)
        k4 = f(h + dt * k3)
        h += dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return h


@pytest.mark.parametrize("h0, current_a, duration_s", [(-1.0, -6.0, 10.0), (0.7, 3.0, 100.0), (0.2, -0.5, 400.0),
                                                       (-0.4, 2.6, 1.0)])
def test_step_is_the_exact_solution(h0, current_a, duration_s):
    rate = 300.0 / 8280.0  # K / Q_p of a 2.3 Ah positive electrode (1/C)
    got = float(ext.hysteresis_step(h0, current_a, duration_s, rate))
    assert got == pytest.approx(_fine(h0, current_a, duration_s, rate), abs=1e-12)
    # steps compose: two halves are one step
    half = ext.hysteresis_step(h0, current_a, duration_s / 2, rate)
    assert float(ext.hysteresis_step(half, current_a, duration_s / 2, rate)) == pytest.approx(got, abs=1e-14)


def test_states_stay_within_the_branches_and_rest_keeps_them():
    rng = np.random.default_rng(3)
    current = rng.normal(0.0, 4.0, 2000)
    current[rng.random(2000) < 0.3] = 0.0
    duration = rng.uniform(0.1, 60.0, 2000)
    h = ext.hysteresis_states(0.3, duration, current, 1e-2)
    assert h.shape == (2001,)
    assert np.all(np.abs(h) <= 1.0)
    rest = np.nonzero(current == 0.0)[0]
    np.testing.assert_array_equal(h[rest + 1], h[rest])
    # the state sequence is the step applied step by step
    again = [0.3]
    for i, d in zip(current, duration):
        again.append(float(ext.hysteresis_step(again[-1], i, d, 1e-2)))
    np.testing.assert_allclose(h, again, rtol=0, atol=1e-13)


def test_charge_and_discharge_move_the_state_towards_their_branch():
    rate = 0.05
    after_discharge = ext.hysteresis_states(0.0, [100.0], [2.0], rate)[-1]
    after_charge = ext.hysteresis_states(0.0, [100.0], [-2.0], rate)[-1]
    assert after_discharge < -0.99 and after_charge > 0.99
    # a switch of direction turns the state round at once, monotonically
    h = ext.hysteresis_states(-1.0, np.full(20, 1.0), np.full(20, -3.0), rate)
    assert np.all(np.diff(h) > 0) and h[-1] <= 1.0


@pytest.fixture(scope="module")
def k2_hysteresis():
    params = load_params(REPO / "docs" / "identification_k2" / "k2_fit_T20C.yaml")
    return replace(params, extensions=(*params.extensions, "hysteresis"),
                   extra={**params.extra, ext.HYS_HALF_WIDTH: 0.02, ext.HYS_DECAY: 300.0, ext.HYS_INITIAL: 0.5})


def _pulses() -> SimulationRequest:
    # discharge, rest, charge, rest, pulses both ways, then a discharge to the cut-off
    current = np.array([2.6, 0.0, -3.0, 0.0, 6.0, 0.0, -6.0, 0.0, 3.0, 0.0, 2.6])
    duration = np.array([600.0, 100.0, 100.0, 100.0, 30.0, 100.0, 30.0, 100.0, 2000.0, 100.0, 4000.0])
    return SimulationRequest(load=StepLoad.from_durations(duration, current), ambient_temperature_k=293.15,
                             initial_soc=0.9, output_time_s=np.arange(0.0, duration.sum(), 5.0))


def test_engine_runs_pybamm_axen_hysteresis_exactly(k2_hysteresis):
    from battery_predictor.simulation.engine import EngineSimulator
    from battery_predictor.simulation.fast import FastPackSimulator

    req = _pulses()
    engine = EngineSimulator(fallback=None).simulate(k2_hysteresis, req)
    pybamm = FastPackSimulator().simulate(k2_hysteresis, req)  # PyBaMM's own Axen model, IDAKLU
    assert "engine_fallback" not in engine.extra and engine.extra["engine_backend"].endswith("+hysteresis")
    assert engine.termination == pybamm.termination == "cell_cutoff"
    assert engine.end_time_s == pytest.approx(pybamm.end_time_s, abs=0.05)
    n = min(engine.time_s.size, pybamm.time_s.size)
    assert np.max(np.abs(engine.pack_voltage_v[:n] - pybamm.pack_voltage_v[:n])) < 2e-4  # V
    h = engine.extra["hysteresis_state"]
    assert np.all(np.abs(h) <= 1.0)
    # the hysteresis voltage is +-M around the run without it
    plain = EngineSimulator(fallback=None).simulate(replace(k2_hysteresis, extensions=()), req)
    m = min(n, plain.time_s.size)
    np.testing.assert_allclose(engine.pack_voltage_v[:m] - plain.pack_voltage_v[:m], 0.02 * h[:m], atol=1e-9)
    # the cut-off is met by the total voltage: the run ends earlier than without the (-M) hysteresis
    assert engine.end_time_s < plain.end_time_s


def test_engine_refuses_hysteresis_on_a_thermal_cell_visibly(k2_hysteresis):
    from battery_predictor.simulation.engine import EngineSimulator

    thermal = replace(k2_hysteresis, options={"thermal": "lumped"})
    reason = EngineSimulator.unsupported_reason(thermal, _pulses())
    assert reason is not None and "hysteresis" in reason
    with pytest.raises(SimulationError, match="hysteresis"):
        EngineSimulator(fallback=None).simulate(thermal, _pulses())
    with pytest.raises(SimulationError, match="hysteresis"):
        EngineSimulator(fallback=None).simulate_batch(k2_hysteresis, _pulses(), {})


def test_fit_coordinates_and_values_of_the_extension(k2_hysteresis):
    from battery_predictor.fitting.identifiable import HYSTERESIS_COORDINATES, default_space, pybamm_values

    names = [c.name for c in default_space(k2_hysteresis)]
    assert set(HYSTERESIS_COORDINATES) <= set(names)
    assert not set(HYSTERESIS_COORDINATES) & {c.name for c in default_space(replace(k2_hysteresis, extensions=()))}
    values = pybamm_values(k2_hysteresis, {"hysteresis_half_width_v": 0.011, "hysteresis_decay_rate": 77.0})[0]
    fitted = k2_hysteresis.with_values(values)
    # the extension's keys live in cell.extra, which wins over cell.fitted: the fitted values must land there
    assert fitted.extra[ext.HYS_HALF_WIDTH] == 0.011 and fitted.extra[ext.HYS_DECAY] == 77.0
    assert ext.HYS_HALF_WIDTH not in fitted.fitted
    assert fitted.cell_values[ext.HYS_HALF_WIDTH] == 0.011
    # params that activate the extension without its keys get them (defaults) in cell.extra before a fit
    bare = replace(k2_hysteresis, extra={k: v for k, v in k2_hysteresis.extra.items() if "hysteresis" not in k})
    ready = ext.with_fitted_extension_keys(bare)
    assert ready.extra[ext.HYS_DECAY] == ext.EXTENSION_DEFAULTS["hysteresis"][ext.HYS_DECAY]
    assert ready.with_values(values).extra[ext.HYS_HALF_WIDTH] == 0.011
    plain = replace(bare, extensions=())
    assert ext.with_fitted_extension_keys(plain) is plain


def test_rate_is_pybamms_axen_rate_per_unit_charge(k2_hysteresis):
    pv = k2_hysteresis.parameter_values()
    q_p = ext.hysteresis_positive_charge_c(pv)
    # Prada2013 scaled: the positive electrode holds about 2.3 Ah
    assert 2.0 * 3600 < q_p < 2.6 * 3600
    assert ext.hysteresis_rate_per_c(k2_hysteresis, pv) == pytest.approx(300.0 / q_p)


@pytest.mark.parametrize("h0, current_a, duration_s, relax", [(1.0, 0.0, 600.0, 1e-3), (-1.0, -6.0, 10.0, 5e-3),
                                                              (0.7, 3.0, 100.0, 2e-2), (0.2, -0.5, 400.0, 1e-3)])
def test_relaxing_step_is_the_exact_solution(h0, current_a, duration_s, relax):
    rate = 300.0 / 8280.0

    def f(h):
        return rate * abs(current_a) * (-np.sign(current_a) - h) - relax * h

    h, n = h0, 20000
    dt = duration_s / n
    for _ in range(n):  # classical Runge-Kutta
        k1 = f(h)
        k2 = f(h + 0.5 * dt * k1)
        k3 = f(h + 0.5 * dt * k2)
        k4 = f(h + dt * k3)
        h += dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    got = float(ext.hysteresis_step(h0, current_a, duration_s, rate, relax))
    assert got == pytest.approx(h, abs=1e-12)
    states = ext.hysteresis_states(h0, [duration_s / 2, duration_s / 2], [current_a, current_a], rate, relax)
    assert states[-1] == pytest.approx(got, abs=1e-14)


def test_new_terms_default_to_the_axen_model(k2_hysteresis):
    # defaults: no relaxation, a half-width that does not depend on the temperature; the step is the old one
    assert ext.extension_value(k2_hysteresis, ext.HYS_RELAX) == 0.0
    assert ext.extension_value(k2_hysteresis, ext.HYS_ACTIVATION) == 0.0
    assert ext.hysteresis_half_width_v(k2_hysteresis, 323.15) == 0.02
    h, i, d = np.array([-1.0, 0.3, 0.5]), np.array([-6.0, 0.0, 2.0]), np.array([10.0, 50.0, 7.0])
    s = -np.sign(i)
    old = np.where(i == 0.0, h, s + (h - s) * np.exp(-0.05 * np.abs(i) * d))
    np.testing.assert_array_equal(ext.hysteresis_step(h, i, d, 0.05), old)
    # the PyBaMM model is PyBaMM's own Axen model (no term added)
    from battery_predictor.simulation.cell_setup import build_model

    model = build_model(k2_hysteresis)
    h_var = model.variables["Positive electrode hysteresis state"]
    assert ext.HYS_RELAX not in str(model.rhs[h_var])


def test_half_width_follows_arrhenius_from_the_anchor(k2_hysteresis):
    warm = replace(k2_hysteresis, extra={**k2_hysteresis.extra, ext.HYS_ACTIVATION: 30000.0,
                                         ext.ANCHOR_TEMPERATURE: 293.15})
    assert ext.hysteresis_half_width_v(warm, 293.15) == pytest.approx(0.02)
    at_50 = ext.hysteresis_half_width_v(warm, 323.15)
    assert at_50 == pytest.approx(0.02 * np.exp(30000.0 / ext.R_GAS * (1 / 323.15 - 1 / 293.15)))
    assert at_50 < 0.02 * 0.35


@pytest.mark.parametrize("temperature_k", [293.15, 318.15])
def test_engine_runs_the_relaxing_temperature_dependent_hysteresis_as_pybamm(k2_hysteresis, temperature_k):
    """The relaxation (``- r h`` added to PyBaMM's Axen ODE) and the Arrhenius half-width: engine = PyBaMM."""
    from battery_predictor.simulation.engine import EngineSimulator
    from battery_predictor.simulation.fast import FastPackSimulator

    params = replace(k2_hysteresis, extra={**k2_hysteresis.extra, ext.HYS_RELAX: 1.0 / 120.0,
                                           ext.HYS_ACTIVATION: 30000.0, ext.ANCHOR_TEMPERATURE: 298.15})
    req = replace(_pulses(), ambient_temperature_k=temperature_k)
    engine = EngineSimulator(fallback=None).simulate(params, req)
    pybamm = FastPackSimulator().simulate(params, req)  # PyBaMM's Axen model with the term added, IDAKLU
    assert "engine_fallback" not in engine.extra and engine.extra["engine_backend"].endswith("+hysteresis")
    assert engine.termination == pybamm.termination == "cell_cutoff"
    assert engine.end_time_s == pytest.approx(pybamm.end_time_s, abs=0.05)
    n = min(engine.time_s.size, pybamm.time_s.size)
    assert np.max(np.abs(engine.pack_voltage_v[:n] - pybamm.pack_voltage_v[:n])) < 2e-4  # V
    # the state relaxes towards 0 in the rests (it stays put without the relaxation)
    h = engine.extra["hysteresis_state"]
    t = engine.time_s
    rest = (t > 935.0) & (t < 1025.0)  # the rest after the 6 A discharge pulse (900-930 s)
    assert np.all(np.diff(h[rest]) > 0.0) and np.all(h[rest] < 0.0)
    # the voltage moves by M(T) h
    plain = EngineSimulator(fallback=None).simulate(replace(params, extensions=()), req)
    m = min(n, plain.time_s.size)
    np.testing.assert_allclose(engine.pack_voltage_v[:m] - plain.pack_voltage_v[:m],
                               ext.hysteresis_half_width_v(params, temperature_k) * h[:m], atol=1e-9)


def test_optional_coordinates_of_the_new_terms(k2_hysteresis):
    from battery_predictor.errors import ParamsError
    from battery_predictor.fitting.identifiable import default_space, pybamm_values

    extra = ("hysteresis_relaxation_rate_s", "hysteresis_activation_energy_j_mol")
    default = [c.name for c in default_space(k2_hysteresis)]
    assert not set(extra) & set(default)  # searched only when asked: existing fits do not move
    space = {c.name: c for c in default_space(k2_hysteresis, extra=extra)}
    relax, energy = space["hysteresis_relaxation_rate_s"], space["hysteresis_activation_energy_j_mol"]
    assert relax.log and relax.initial == relax.low  # the params' 0 (no relaxation) starts at the low end
    assert not energy.log and energy.initial == 0.0
    values = pybamm_values(k2_hysteresis, {"hysteresis_relaxation_rate_s": 2e-3,
                                           "hysteresis_activation_energy_j_mol": 25000.0})[0]
    fitted = ext.with_fitted_extension_keys(k2_hysteresis).with_values(values)
    assert fitted.extra[ext.HYS_RELAX] == 2e-3 and fitted.extra[ext.HYS_ACTIVATION] == 25000.0
    with pytest.raises(ParamsError, match="hysteresis"):
        default_space(replace(k2_hysteresis, extensions=()), extra=extra[:1])
