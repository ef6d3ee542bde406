"""fitting.problem.trim_to_discharge: a recording cut at the end of the discharge that holds its minimum voltage."""

from __future__ import annotations

import numpy as np
import pytest

from battery_predictor.errors import InputDataError
from battery_predictor.fitting.problem import CHARGE_SESSION_S, trim_to_discharge
from battery_predictor.recording import Recording


def _recording(segments: list[tuple[float, float, float]]) -> Recording:
    """1 s samples of ``[(duration_s, current_a, voltage_v), ...]`` (current > 0 = discharge)."""
    current = np.concatenate([np.full(int(d), i) for d, i, _ in segments])
    voltage = np.concatenate([np.full(int(d), v) for d, _, v in segments])
    voltage = voltage - 1e-5 * np.arange(voltage.size) * (current > 0)  # a discharge lowers the voltage slowly
    return Recording(np.arange(current.size, dtype=float), voltage, current, source="synthetic")


def test_a_burst_before_the_end_keeps_the_discharge_that_follows_it() -> None:
    # the lowest voltage is a 17 A burst at 300 s; the drive goes on at 2 A for 300 s more, then rests
    rec = _recording([(300, 2.0, 3.4), (5, 17.0, 2.6), (300, 2.0, 3.3), (200, 0.0, 3.5)])
    trimmed = trim_to_discharge(rec)
    assert trimmed.time_s[-1] == pytest.approx(604.0)
    assert trimmed.current_a[-1] == pytest.approx(2.0)


def test_regenerative_pulses_do_not_end_the_discharge() -> None:
    rec = _recording([(300, 2.0, 3.4), (5, 17.0, 2.6), (15, -5.0, 3.5), (300, 2.0, 3.3), (15, -5.0, 3.5),
                      (100, 2.0, 3.25), (200, 0.0, 3.5)])
    assert trim_to_discharge(rec).time_s[-1] == pytest.approx(734.0)


def test_a_recharge_after_the_minimum_ends_the_discharge_before_it() -> None:
    rec = _recording([(300, 2.0, 3.4), (5, 17.0, 2.6), (100, 2.0, 3.3), (60, 0.0, 3.5),
                      (int(CHARGE_SESSION_S) + 10, -3.0, 3.9), (300, 2.0, 3.8)])
    trimmed = trim_to_discharge(rec)
    assert trimmed.time_s[-1] == pytest.approx(404.0)
    assert np.all(trimmed.current_a > 0)


def test_a_discharge_that_ends_at_its_minimum_is_cut_there() -> None:
    rec = _recording([(600, 2.0, 3.4), (120, 0.0, 3.6)])
    trimmed = trim_to_discharge(rec)
    assert trimmed.time_s[-1] == pytest.approx(599.0)
    assert trimmed.voltage_v[-1] == pytest.approx(float(np.min(rec.voltage_v)))


def test_a_minimum_at_the_start_is_a_clear_error() -> None:
    rec = _recording([(10, 0.0, 2.0), (100, -1.0, 3.5)])
    with pytest.raises(InputDataError, match="minimum voltage is at the start"):
        trim_to_discharge(rec)
