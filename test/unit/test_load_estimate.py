"""Load estimation of the present discharge cycle: regen and blips stay in it, charging sessions end it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.io.loader import load_recording
from battery_predictor.monitor.core import monitor_windows
from battery_predictor.prediction.load_estimate import LoadEstimator, heavy_run_s

PANASONIC = Path(__file__).resolve().parents[3] / "shared" / "data" / "panasonic_18650pf"


def feed(est: LoadEstimator, time_s, current_a) -> int:
    """Feed samples; returns how many charging sessions began."""
    return sum(est.add(float(t), float(i)) for t, i in zip(time_s, current_a))


def net_mean_a(time_s, current_a, charge_current_a: float = 0.2) -> float:
    """Time-weighted mean current from the first discharge on (each window holds until the next)."""
    t, i = np.asarray(time_s, float), np.asarray(current_a, float)
    first = int(np.argmax(i > charge_current_a))
    t, i = t[first:], i[first:]
    return float(np.sum(np.diff(t) * i[:-1]) / (t[-1] - t[0]))


def test_regen_pulses_stay_in_the_cycle_and_enter_the_mean_as_negative_current():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 3600.0, 5.0)
    i = np.where(rng.random(t.size) < 0.2, -rng.uniform(0.5, 4.0, t.size), rng.uniform(0.5, 6.0, t.size))
    est = LoadEstimator(charge_current_a=0.2)
    assert feed(est, t, i) == 0
    assert est.estimate().mean_current_a == pytest.approx(net_mean_a(t, i), rel=1e-9)
    assert not est.estimate().charging


def test_rest_before_the_first_discharge_is_not_part_of_the_load():
    t = np.arange(0.0, 7200.0, 5.0)
    i = np.where(t < 3600.0, 0.0, 2.0)  # an hour's soak, then a 2 A discharge
    est = LoadEstimator(charge_current_a=0.2)
    feed(est, t, i)
    assert est.estimate().mean_current_a == pytest.approx(2.0)


def test_a_charging_session_ends_the_cycle_and_the_next_discharge_starts_afresh():
    est = LoadEstimator(charge_current_a=0.2, charge_session_s=300.0)
    feed(est, np.arange(0.0, 600.0, 5.0), np.full(120, 3.0))
    assert est.estimate().mean_current_a == pytest.approx(3.0)
    began = feed(est, np.arange(600.0, 1200.0, 5.0), np.full(120, -4.0))
    assert began == 1 and est.estimate().charging and est.estimate().charging_current_a == -4.0
    feed(est, np.arange(1200.0, 1300.0, 5.0), np.full(20, 1.0))
    after = est.estimate()
    assert not after.charging and after.mean_current_a == pytest.approx(1.0)
    assert after.duration_s == pytest.approx(95.0)


def test_charging_shorter_than_a_session_is_a_blip_not_a_new_cycle():
    est = LoadEstimator(charge_current_a=0.2, charge_session_s=300.0)
    t = np.arange(0.0, 1200.0, 5.0)
    i = np.full(t.size, 2.0)
    i[(t >= 400) & (t < 690)] = -3.0  # 290 s of charging: below the session length
    assert feed(est, t, i) == 0
    assert est.estimate().mean_current_a == pytest.approx(net_mean_a(t, i), rel=1e-9)


def test_ewma_follows_a_change_of_usage_the_cycle_mean_does_not():
    t = np.arange(0.0, 4 * 3600.0, 5.0)
    i = np.where(t < 2 * 3600.0, 1.0, 4.0)
    cycle, ewma = LoadEstimator(0.2), LoadEstimator(0.2, estimator="ewma", time_constant_s=900.0)
    feed(cycle, t, i)
    feed(ewma, t, i)
    assert cycle.estimate().mean_current_a == pytest.approx(2.5, abs=0.01)
    assert ewma.estimate().mean_current_a == pytest.approx(4.0, abs=0.01)


def test_young_ewma_equals_the_cycle_mean():
    t = np.arange(0.0, 60.0, 5.0)
    i = np.linspace(1.0, 3.0, t.size)
    cycle, ewma = LoadEstimator(0.2), LoadEstimator(0.2, estimator="ewma", time_constant_s=1e6)
    feed(cycle, t, i)
    feed(ewma, t, i)
    assert ewma.estimate().mean_current_a == pytest.approx(cycle.estimate().mean_current_a, rel=1e-4)


def test_no_sample_gives_no_estimate_and_an_unknown_estimator_is_refused():
    assert math.isnan(LoadEstimator(0.2).estimate().mean_current_a)
    with pytest.raises(ValueError, match="not one of"):
        LoadEstimator(0.2, estimator="median")


@pytest.mark.skipif(not PANASONIC.is_dir(), reason="measured data not available (../shared/data)")
def test_regen_on_a_measured_drive_cycle_does_not_reset_the_load_estimate():
    rec = load_recording(PANASONIC / "drive_T25C_US06.csv")
    windows = monitor_windows(rec.time_s, rec.voltage_v, rec.current_a)
    t = np.array([w.stamp_s for w in windows])
    i = np.array([w.current_a for w in windows])
    assert np.sum(i < -0.2) > 50, "the drive cycle has regen windows"
    est = LoadEstimator(charge_current_a=0.2)
    discharge = t <= t[0] + 0.6 * (t[-1] - t[0])
    assert feed(est, t[discharge], i[discharge]) == 0
    estimate = est.estimate().mean_current_a
    assert estimate == pytest.approx(net_mean_a(t[discharge], i[discharge]), rel=1e-9)
    assert 1.0 < estimate < 3.0  # a US06 cell load, not a few seconds' worth


def test_mean_power_is_time_weighted_from_the_window_voltages():
    est = LoadEstimator(0.2)
    for t, i, v in [(0.0, 1.0, 10.0), (100.0, 1.25, 8.0), (200.0, 0.0, 9.0), (300.0, 1.0, 10.0)]:
        est.add(t, i, math.nan, v)
    load = est.estimate()
    assert load.mean_power_w == pytest.approx((10.0 + 10.0 + 0.0) / 3)
    assert load.mean_current_a == pytest.approx((1.0 + 1.25 + 0.0) / 3)
    no_voltage = LoadEstimator(0.2)
    feed(no_voltage, [0.0, 10.0], [1.0, 1.0])
    assert math.isnan(no_voltage.estimate().mean_power_w)


@pytest.mark.skipif(not PANASONIC.is_dir(), reason="measured data not available (../shared/data)")
def test_repeated_drive_cycles_draw_a_constant_power_not_a_constant_current():
    rec = load_recording(PANASONIC / "drive_T25C_HWFET.csv")
    t, i, v = rec.time_s - rec.time_s[0], rec.current_a, rec.voltage_v
    period_s = 1536.0  # one repetition of the file's drive pattern (its autocorrelation peak)
    first, last = t < period_s, (t >= 3 * period_s) & (t < 4 * period_s)
    current = [float(np.mean(i[m])) for m in (first, last)]
    power = [float(np.mean((i * v)[m])) for m in (first, last)]
    assert current[1] / current[0] > 1.1  # the current rises as the voltage falls ...
    assert power[1] / power[0] == pytest.approx(1.0, abs=0.01)  # ... at a constant power


def _windows(kind: str, seed: int, hours: float = 6.0):
    """5 s windows of a random usage (1.5..2.5 A demand levels held 60 s) on a pack whose open-circuit
    voltage falls from 16.4 to 13.3 V; the demand is drawn as a current or as a power."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, hours * 3600.0, 5.0)
    level = np.repeat(rng.uniform(1.5, 2.5, t.size // 12 + 1), 12)[: t.size]
    ocv = 16.4 - 3.1 * t / t[-1]
    r_ohm = 0.1
    if kind == "current":
        i = level
    else:
        power = level * 15.0
        i = (ocv - np.sqrt(ocv ** 2 - 4 * r_ohm * power)) / (2 * r_ohm)  # P = I (OCV - I R)
    v = ocv - i * r_ohm
    return t, i, v, r_ohm


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_load_kind_tells_a_current_load_from_a_power_load(seed):
    from battery_predictor.prediction.load_estimate import load_kind

    for kind, expected in (("current", 0.0), ("power", 1.0)):
        t, i, v, r_ohm = _windows(kind, seed)
        found = load_kind(t, i, v, r_ohm, prior=0.5)
        assert found.decided and abs(found.exponent - expected) <= 0.3, (kind, found)
    t, i, v, r_ohm = _windows("current", seed, hours=0.5)
    early = load_kind(t, i, v, r_ohm, prior=0.7)
    assert not early.decided and early.exponent == 0.7  # too few windows: the prior


@pytest.mark.skipif(not PANASONIC.is_dir(), reason="measured data not available (../shared/data)")
def test_load_kind_finds_a_power_load_in_measured_drive_cycles():
    from battery_predictor.prediction.load_estimate import load_kind

    for name in ("drive_T25C_HWFET.csv", "drive_T25C_LA92.csv"):
        rec = load_recording(PANASONIC / name)
        windows = monitor_windows(rec.time_s, rec.voltage_v, rec.current_a)
        t = np.array([w.stamp_s for w in windows])
        i = np.array([w.current_a for w in windows])
        v = np.array([w.voltage_v for w in windows])
        found = load_kind(t, i, v, 0.05, prior=1.0)
        assert found.z_current > 1.5 and abs(found.z_power) < 1.0, (name, found)  # the current trends, the power not
        assert found.exponent >= 0.7, (name, found)  # never taken for a current load


def test_a_constant_current_discharge_is_a_current_load():
    from battery_predictor.prediction.load_estimate import load_kind

    t = np.arange(0.0, 3600.0, 5.0)
    i = np.full(t.size, 5.0)
    v = 4.1 - 0.8 * t / t[-1]
    found = load_kind(t, i, v, 0.02, prior=1.0)
    assert found.decided and found.exponent == 0.0
    early = load_kind(t[:120], i[:120] + 0.001 * np.sin(t[:120]), v[:120], 0.02, prior=1.0)  # 10 min, sensor noise
    assert early.decided and early.exponent == 0.0
    power = load_kind(t, 20.0 / v, v, 0.0, prior=0.0)  # a constant-power test
    assert power.decided and power.exponent == 1.0


def test_heavy_run_is_one_window_for_spikes_and_the_state_length_for_held_states():
    t = np.arange(720) * 5.0
    spikes = np.where(np.arange(720) % 12 == 0, 4.0, 1.5)  # one heavy 5 s window a minute
    assert heavy_run_s(t, spikes, 0.9) == pytest.approx(5.0)
    states = np.where((np.arange(720) // 24) % 5 == 0, 3.0, 1.0)  # 2 min at 3 A every 10 min
    assert heavy_run_s(t, states, 0.9) == pytest.approx(120.0)


def test_a_gap_between_windows_ends_a_heavy_run():
    t = np.concatenate([np.arange(10) * 5.0, 1000.0 + np.arange(10) * 5.0])
    i = np.concatenate([np.full(10, 1.0), np.full(10, 1.0)])
    i[6:14] = 3.0  # eight heavy windows across the gap: two runs of four
    assert heavy_run_s(t, i, 0.5) == pytest.approx(20.0)


def test_heavy_run_needs_two_discharge_windows():
    assert math.isnan(heavy_run_s([0.0, 5.0, 10.0], [-1.0, 0.0, 2.0], 0.9))
    assert math.isnan(heavy_run_s([], [], 0.9))
