"""Battery monitor logic without ROS: validation, 5 s windows, staleness, diagnostics levels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from battery_predictor.monitor.core import ERROR, OK, REASONS, WARN, BatteryMonitor, MonitorConfig

T0 = 1_704_067_200.0  # 2024-01-01T00:00:00Z, a multiple of the 5 s window


def ranger(**kw) -> BatteryMonitor:
    cfg = dict(input_style="battery_state", min_voltage_v=37.5, max_voltage_v=58.0, max_discharge_current_a=30.0,
               max_charge_current_a=15.0, window_s=5.0, stale_after_s=15.0, late_allowance_s=1.0, max_future_s=2.0,
               error_hold_s=10.0)
    cfg.update(kw)
    return BatteryMonitor(MonitorConfig(**cfg))


def feed(mon: BatteryMonitor, times, volts, amps, temps=None):
    """BatteryState samples stamped ``times`` (clock = stamp); returns the emitted snapshots."""
    out = []
    for k, t in enumerate(times):
        temp = math.nan if temps is None else temps[k]
        out += mon.add_sample(t, volts[k], amps[k], temp, now_s=t).snapshots
    return out


# --- config ------------------------------------------------------------------


@pytest.mark.parametrize("kw", [
    {"input_style": "can_bus"},
    {"min_voltage_v": 50.0, "max_voltage_v": 40.0},
    {"window_s": 0.0},
    {"stale_after_s": -1.0},
    {"max_charge_current_a": -1.0},
    {"max_voltage_v": math.nan},
    {"min_temperature_k": 400.0, "max_temperature_k": 300.0},
])
def test_config_rejects_nonsense(kw):
    with pytest.raises(ValueError):
        MonitorConfig(**kw)


# --- windows -----------------------------------------------------------------


def test_samples_are_averaged_into_windows_stamped_at_their_end():
    mon = ranger()
    times = T0 + np.arange(0.0, 10.0, 0.5)  # 10 samples in each of two windows
    volts = np.where(times < T0 + 5, 50.0, 49.0) + np.tile([-0.1, 0.1], 10)
    amps = np.where(times < T0 + 5, 2.0, 4.0)
    temps = np.full(20, 300.0)
    snaps = feed(mon, times, volts, amps, temps)
    # the first window is closed by the first sample of the second one
    assert len(snaps) == 1
    first = snaps[0]
    assert first.stamp_s == T0 + 5.0
    assert first.voltage_v == pytest.approx(50.0)
    assert first.current_a == pytest.approx(2.0)
    assert first.temperature_k == pytest.approx(300.0)
    assert (first.samples_used, first.samples_rejected, first.stale) == (10, 0, False)
    assert first.window_s == 5.0
    # the second one is closed by tick once late_allowance_s has passed after its end
    assert mon.tick(T0 + 10.5) == []
    (second,) = mon.tick(T0 + 11.0)
    assert second.stamp_s == T0 + 10.0
    assert second.voltage_v == pytest.approx(49.0)
    assert second.current_a == pytest.approx(4.0)


def test_unmeasured_temperature_is_nan_not_a_rejection():
    mon = ranger()
    snaps = feed(mon, [T0, T0 + 5.0], [50.0, 50.0], [2.0, 2.0])
    assert math.isnan(snaps[0].temperature_k)
    assert mon.rejected_total == 0


def test_out_of_range_temperature_drops_only_the_temperature():
    mon = ranger()
    snaps = feed(mon, [T0, T0 + 1, T0 + 5], [50.0, 50.0, 50.0], [2.0, 2.0, 2.0], [300.0, 500.0, 300.0])
    assert snaps[0].samples_used == 2 and snaps[0].temperature_k == pytest.approx(300.0)
    assert mon.rejected == {"temperature": {"out_of_range": 1}}


def test_relay_inputs_are_averaged_separately_and_need_voltage_and_current():
    mon = BatteryMonitor(MonitorConfig(input_style="relay", min_voltage_v=10.0, max_voltage_v=17.0))
    for k in range(10):
        t = T0 + 0.5 * k
        mon.add_voltage(t, 14.0 + 0.01 * k, t)
        mon.add_current(t, 1.5, t)
        if k % 5 == 0:
            mon.add_temperature(t, 299.0, t)
    # a window with voltage only gives no state
    mon.add_voltage(T0 + 5.0, 14.0, T0 + 5.0)
    snaps = mon.tick(T0 + 11.0)
    assert len(snaps) == 0  # the second window had no current
    assert mon.snapshots_emitted == 1
    status = mon.status(T0 + 11.0)
    assert status.accepted == {"voltage": 11, "current": 10, "temperature": 2}
    assert status.last_snapshot.voltage_v == pytest.approx(14.045)
    assert status.last_snapshot.current_a == pytest.approx(1.5)
    assert status.last_snapshot.temperature_k == pytest.approx(299.0)
    assert status.last_snapshot.samples_used == 22  # messages on all three topics


# --- validation --------------------------------------------------------------


@pytest.mark.parametrize(("voltage", "current", "reason"), [
    (math.nan, 2.0, "nan"),
    (50.0, math.inf, "nan"),
    (-math.inf, 2.0, "nan"),
    (12.0, 2.0, "out_of_range"),
    (60.0, 2.0, "out_of_range"),
    (50.0, 31.0, "out_of_range"),
    (50.0, -16.0, "out_of_range"),
])
def test_invalid_samples_are_rejected_counted_and_never_averaged(voltage, current, reason):
    mon = ranger()
    verdict = mon.add_sample(T0 + 1.0, voltage, current, math.nan, T0 + 1.0)
    assert (verdict.accepted, verdict.reason) == (False, reason)
    feed(mon, [T0 + 2.0, T0 + 5.0], [50.0, 50.0], [2.0, 2.0])
    status = mon.status(T0 + 5.0)
    assert status.rejected == {"battery_state": {reason: 1}}
    assert status.last_snapshot.voltage_v == 50.0 and status.last_snapshot.current_a == 2.0
    assert status.last_snapshot.samples_rejected == 0  # rejected before the window opened
    assert status.level == ERROR
    assert dict(status.key_values())[f"rejected_{reason}"] == "1"


def test_rejections_inside_a_window_are_reported_with_it():
    mon = ranger()
    feed(mon, [T0], [50.0], [2.0])
    mon.add_sample(T0 + 1.0, math.nan, 2.0, math.nan, T0 + 1.0)
    mon.add_sample(T0 + 2.0, 50.0, 99.0, math.nan, T0 + 2.0)
    (snap,) = feed(mon, [T0 + 5.0], [49.0], [2.0])
    assert (snap.samples_used, snap.samples_rejected) == (1, 2)


def test_time_going_backwards_duplicates_late_and_future_samples():
    mon = ranger()
    feed(mon, [T0 + 3.0], [50.0], [2.0])
    assert mon.add_sample(T0 + 3.0, 50.0, 2.0, math.nan, T0 + 3.5).reason == "duplicate"
    assert mon.add_sample(T0 + 2.0, 50.0, 2.0, math.nan, T0 + 3.5).reason == "out_of_order"
    assert mon.add_sample(T0 + 9.0, 50.0, 2.0, math.nan, T0 + 4.0).reason == "future"
    assert mon.tick(T0 + 6.0)  # closes [T0, T0 + 5)
    # a relay-style input whose window is already closed: late
    mon2 = BatteryMonitor(MonitorConfig(input_style="relay"))
    mon2.add_voltage(T0 + 5.1, 14.0, T0 + 5.1)
    mon2.add_current(T0 + 5.1, 1.0, T0 + 5.1)
    mon2.add_voltage(T0 + 10.2, 14.0, T0 + 10.2)  # closes [T0 + 5, T0 + 10)
    assert mon2.add_current(T0 + 9.9, 1.0, T0 + 10.2).reason == "late"
    status = mon.status(T0 + 6.0)
    assert status.rejected == {"battery_state": {"duplicate": 1, "out_of_order": 1, "future": 1}}
    assert status.level == WARN
    assert set(REASONS) >= set(status.rejected["battery_state"])


# --- staleness and diagnostics -----------------------------------------------


def test_stale_input_emits_stale_states_with_the_last_values_and_recovers():
    mon = ranger()
    feed(mon, T0 + np.arange(0.0, 10.0, 1.0), [50.0] * 10, [2.0] * 10, [300.0] * 10)
    mon.tick(T0 + 11.0)
    assert not mon.is_stale(T0 + 24.0)
    assert mon.status(T0 + 24.0).level == OK
    snaps = mon.tick(T0 + 25.0)  # last sample at T0 + 9, 16 s ago
    assert len(snaps) == 1 and snaps[0].stale
    assert (snaps[0].voltage_v, snaps[0].current_a, snaps[0].temperature_k) == (50.0, 2.0, 300.0)
    assert snaps[0].stamp_s == T0 + 25.0 and snaps[0].samples_used == 0
    assert mon.tick(T0 + 27.0) == []  # one stale state per window
    assert len(mon.tick(T0 + 30.0)) == 1
    status = mon.status(T0 + 30.0)
    assert status.stale and status.level == WARN and "stale" in status.message
    # fresh input: not stale any more
    feed(mon, [T0 + 31.0, T0 + 35.0], [49.0, 49.0], [2.0, 2.0])
    assert not mon.is_stale(T0 + 35.0)
    assert mon.status(T0 + 35.0).level == OK


def test_no_input_yet_is_stale_without_states():
    mon = ranger()
    assert mon.is_stale(T0) and mon.tick(T0 + 100.0) == []
    status = mon.status(T0 + 100.0)
    assert status.level == WARN and status.message == "no input received yet"
    assert math.isinf(status.age_s)


def test_invalid_only_input_becomes_stale_and_error():
    mon = ranger()
    feed(mon, [T0, T0 + 5.0], [50.0, 50.0], [2.0, 2.0])
    for k in range(1, 40):
        mon.add_sample(T0 + 5.0 + 0.5 * k, math.nan, 2.0, math.nan, T0 + 5.0 + 0.5 * k)
    status = mon.status(T0 + 25.0)
    assert status.level == ERROR and status.stale
    assert "invalid" in status.message and "stale" in status.message
    assert status.rejected_total == 39
    # ERROR is held for error_hold_s after the last invalid sample, then only the staleness remains
    assert mon.status(T0 + 24.5 + 10.1).level == WARN


def test_clock_jumping_back_resets_the_monitor():
    mon = ranger()
    feed(mon, [T0, T0 + 5.0], [50.0, 50.0], [2.0, 2.0])
    mon.tick(T0 - 3600.0)  # a replay restarted
    assert mon.rejected_total == 0 and mon.snapshots_emitted == 0
    assert mon.add_sample(T0 - 3599.0, 50.0, 2.0, math.nan, T0 - 3599.0).accepted


def test_random_garbage_never_reaches_the_averages():
    rng = np.random.default_rng(3)
    mon = ranger()
    n = 2000
    times = T0 + np.arange(n) * 0.1
    volts = rng.uniform(45.0, 54.0, n)
    amps = rng.uniform(0.5, 8.0, n)
    bad = rng.random(n) < 0.2
    garbage = rng.choice([math.nan, math.inf, -5.0, 1000.0], n)
    volts_in = np.where(bad, garbage, volts)
    snaps = feed(mon, times, volts_in, amps)
    for s in snaps:
        in_window = (times >= s.stamp_s - 5.0) & (times < s.stamp_s) & ~bad
        assert s.voltage_v == pytest.approx(volts[in_window].mean())
        assert s.samples_used == in_window.sum()
    assert mon.rejected_total == bad.sum()


def test_windows_carry_their_largest_sample_current_and_offline_windows_match_the_monitor():
    from battery_predictor.monitor.core import monitor_windows

    t = np.arange(0.0, 20.0, 1.0)
    i = np.array([1.0, 3.0, 2.0, -1.0, 1.5] * 4)
    v = np.full(t.size, 15.0)
    snaps = monitor_windows(t, v, i)
    assert [s.stamp_s for s in snaps] == [5.0, 10.0, 15.0, 20.0]
    assert all(s.peak_current_a == 3.0 and s.current_a == pytest.approx(1.3) for s in snaps)
    assert all(not s.stale for s in snaps)
