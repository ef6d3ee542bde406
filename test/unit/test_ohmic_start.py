"""The data's step resistance and the ohmic structure ``fit`` identifies beside the params' own (issue 17)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import ParamsError
from battery_predictor.fitting import identifiable
from battery_predictor.fitting.identifiable import (
    KINETIC_SCALE_RANGE,
    default_space,
    ohmic_structure,
    pybamm_values,
    with_start_value,
)
from battery_predictor.fitting.resample import resample_windows
from battery_predictor.params import load_params
from battery_predictor.recording import Recording, ohmic_resistance_estimate, step_resistance_ohm

REPO = Path(__file__).resolve().parents[2]


def _stepped_recording(r_ohm: float, seed: int = 0, n: int = 3000, tau_s: float = 30.0) -> Recording:
    """1 s samples of a cell with an ohmic step ``r_ohm`` and a slower polarisation (RC, 10 mOhm, ``tau_s``)."""
    rng = np.random.default_rng(seed)
    t = np.arange(float(n))
    i = np.repeat(rng.choice([0.5, 2.0, 5.0, 8.0, -2.0], size=n // 20), 20)[:n]
    polarisation = np.zeros(n)
    for k in range(1, n):
        polarisation[k] = polarisation[k - 1] + (0.010 * i[k] - polarisation[k - 1]) * (1.0 - np.exp(-1.0 / tau_s))
    v = 4.0 - 2e-4 * t / 10.0 - r_ohm * i - polarisation + rng.normal(0.0, 1e-4, n)
    return Recording(t, v, i, source=f"stepped{seed}.csv")


def test_the_step_resistance_of_data_with_steps_is_their_ohmic_resistance():
    rec = _stepped_recording(0.030)
    assert step_resistance_ohm([rec]) == pytest.approx(0.030, rel=0.05)
    assert step_resistance_ohm([rec]) == pytest.approx(ohmic_resistance_estimate(rec))


def test_recordings_pool_their_steps():
    a, b = _stepped_recording(0.020, seed=1), _stepped_recording(0.040, seed=2, n=9000)
    pooled = step_resistance_ohm([a, b])
    assert ohmic_resistance_estimate(b) * 0.95 < pooled <= ohmic_resistance_estimate(b) * 1.05  # b has 3x the steps


def test_the_current_noise_of_a_constant_current_discharge_is_no_step():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 3000.0)
    # 2 A with a 10 mA reading noise; the voltage noise does not follow the current (no resistance in it)
    cc = Recording(t, 4.1 - 1e-4 * t + rng.normal(0.0, 1e-3, t.size), 2.0 + rng.normal(0.0, 0.01, t.size),
                   source="cc.csv")
    assert step_resistance_ohm([cc]) == 0.0
    pulses = _stepped_recording(0.030, n=600)
    assert step_resistance_ohm([cc, pulses]) == pytest.approx(0.030, rel=0.05)
    assert step_resistance_ohm([resample_windows(cc, 5.0), resample_windows(pulses, 5.0)]) == pytest.approx(
        step_resistance_ohm([cc, pulses]))


def test_window_averages_keep_the_step_resistance_of_the_samples_as_measured():
    rec = _stepped_recording(0.030, tau_s=3.0)
    averaged = resample_windows(rec, 5.0)
    # a 5 s average mixes the step with the first seconds of polarisation ...
    assert ohmic_resistance_estimate(averaged) > 0.034
    # ... the estimate the fit uses is still the samples' step
    assert step_resistance_ohm([averaged]) == pytest.approx(step_resistance_ohm([rec]), rel=1e-9)
    assert step_resistance_ohm([resample_windows(averaged, 10.0)]) == pytest.approx(step_resistance_ohm([rec]),
                                                                                    rel=1e-9)


@pytest.fixture(scope="module")
def panasonic():
    return load_params(REPO / "params" / "panasonic_18650pf.yaml")


def test_a_constant_current_discharge_has_no_step_and_no_ohmic_structure(panasonic):
    t = np.arange(0.0, 3600.0)
    rec = Recording(t, 4.1 - 1e-4 * t, np.full(t.size, 2.0), source="cc.csv")
    assert step_resistance_ohm([rec]) == 0.0
    assert ohmic_structure(panasonic, [rec]) is None


def test_the_ohmic_structure_has_the_fastest_kinetics_and_the_same_capacity_and_diffusion_time(panasonic):
    structure = ohmic_structure(panasonic, [_stepped_recording(0.030)])
    assert structure is not None
    fast, step_ohm = structure
    assert step_ohm == pytest.approx(0.030, rel=0.05)
    pv, fast_pv = panasonic.parameter_values(), fast.parameter_values()
    for electrode in ("Negative", "Positive"):
        radius, diffusivity = f"{electrode} particle radius [m]", f"{electrode} particle diffusivity [m2.s-1]"
        assert fast_pv[radius] == pytest.approx(pv[radius] / KINETIC_SCALE_RANGE[1])
        assert fast_pv[radius] ** 2 / fast_pv[diffusivity] == pytest.approx(pv[radius] ** 2 / pv[diffusivity])
    assert pybamm_values(fast, {})[0] == pytest.approx(pybamm_values(panasonic, {})[0])  # capacities, state


def test_without_a_scalable_electrode_there_is_no_ohmic_structure(panasonic, monkeypatch):
    def unscalable(params, name):
        raise ParamsError(f"{name}: a function")

    monkeypatch.setattr(identifiable, "_check_kinetic_scalable", unscalable)
    assert ohmic_structure(panasonic, [_stepped_recording(0.030)]) is None


def test_a_start_value_is_clipped_into_its_box_and_leaves_the_other_coordinates(panasonic):
    space = default_space(panasonic, [_stepped_recording(0.030)])
    moved = with_start_value(space, "series_resistance_ohm", 0.030)
    for before, after in zip(space, moved, strict=True):
        assert (before.low, before.high) == (after.low, after.high)
        if before.name == "series_resistance_ohm":
            assert after.initial == pytest.approx(0.030)
        else:
            assert after == before
    assert with_start_value(space, "series_resistance_ohm", 1e3)[3].initial == space[3].high
