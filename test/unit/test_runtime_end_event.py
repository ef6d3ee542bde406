"""Where a load with peaks ends: the peak-load crossing and the futures resampled from the cycle's windows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.prediction.calibration import calibrate_soc
from battery_predictor.prediction.core import PredictorConfig, PredictorCore
from battery_predictor.prediction.pack_model import pack_model
from battery_predictor.prediction.runtime import (
    SAMPLED_MIN_HISTORY_S,
    LoadPath,
    predict_remaining_runtime,
    sampled_end_s,
    sampled_ends_s,
)

PARAMS = Path(__file__).resolve().parents[2] / "params"
WINDOW_S = 5.0


@pytest.fixture(scope="module")
def temi_engine():
    model, why = pack_model(load_params(PARAMS / "temi.yaml"), "engine")
    return model


@pytest.fixture(scope="module")
def half_full(temi_engine):
    return calibrate_soc(temi_engine, 15.3, 1.5, 298.15)


def _rare_heavy_states(hours: float = 4.0) -> np.ndarray:
    """Window currents of a day at 1.2 A with one 10 min state at 3.5 A: its 0.99 quantile is the rare state."""
    n = int(hours * 3600 / WINDOW_S)
    history = np.full(n, 1.2)
    history[n // 2: n // 2 + 120] = 3.5
    return history


def _bursts(hours: float = 1.0) -> np.ndarray:
    """Window currents at 1.5 A with a 4 A window every minute: the heavy load recurs all the time."""
    history = np.full(int(hours * 3600 / WINDOW_S), 1.5)
    history[::12] = 4.0
    return history


def _answers(runner, cal, history):
    mean_a = float(np.mean(history))
    kwargs = dict(calibration=cal, peak_current_a=float(np.quantile(history, 0.99)), peak_duration_s=WINDOW_S)
    peak = predict_remaining_runtime(runner, 15.0, mean_a, 298.15, mean_a, 13.30, **kwargs)
    sampled = predict_remaining_runtime(runner, 15.0, mean_a, 298.15, mean_a, 13.30, end_event="sampled",
                                        load_history_a=history, history_window_s=WINDOW_S, **kwargs)
    return peak, sampled


def test_a_rare_heavy_state_ends_the_sampled_futures_later_than_a_peak_that_could_come_at_any_moment(
        temi_engine, half_full):
    peak, sampled = _answers(temi_engine, half_full, _rare_heavy_states())
    assert peak.limited_by == "peak_cutoff" and sampled.limited_by == "sampled_cutoff"
    assert peak.remaining_s + 600.0 < sampled.remaining_s <= sampled.average_end_s + 1.0


def test_a_heavy_window_every_minute_ends_the_sampled_futures_near_the_peak_load_crossing(temi_engine, half_full):
    peak, sampled = _answers(temi_engine, half_full, _bursts())
    assert sampled.limited_by == "sampled_cutoff"
    assert abs(sampled.remaining_s - peak.remaining_s) < 300.0
    assert sampled.remaining_s < sampled.average_end_s - 600.0  # well before the average load's crossing


def test_the_same_state_and_history_give_the_same_sampled_answer(temi_engine, half_full):
    history = _rare_heavy_states()
    _, sampled = _answers(temi_engine, half_full, history)
    path = LoadPath.constant(float(np.mean(history)), 2.0 * sampled.average_end_s)
    again = sampled_end_s(temi_engine, half_full.start, history, WINDOW_S, path, 298.15, 13.30, sampled.average_end_s)
    assert again == sampled.remaining_s


def test_the_sampled_answer_is_the_quantile_of_every_futures_end(temi_engine, half_full):
    history = _bursts()
    _, sampled = _answers(temi_engine, half_full, history)
    path = LoadPath.constant(float(np.mean(history)), 2.0 * sampled.average_end_s)
    args = (temi_engine, half_full.start, history, WINDOW_S, path, 298.15, 13.30, sampled.average_end_s)
    ends = sampled_ends_s(*args, futures=8)
    assert ends.shape == (8,) and np.all(ends > 0)
    assert sampled_end_s(*args, futures=8, quantile=0.75) == float(np.quantile(ends, 0.75, method="inverted_cdf"))


def test_a_history_shorter_than_the_minimum_keeps_the_peak_load_crossing(temi_engine, half_full):
    short = _bursts(hours=0.9 * SAMPLED_MIN_HISTORY_S / 3600.0)
    peak, sampled = _answers(temi_engine, half_full, short)
    assert sampled.limited_by == "peak_cutoff" and sampled.remaining_s == peak.remaining_s


def test_a_history_that_charges_on_average_has_no_sampled_answer(temi_engine, half_full):
    path = LoadPath.constant(1.0, 8 * 3600.0)
    assert sampled_end_s(temi_engine, half_full.start, np.full(600, -0.5), WINDOW_S, path, 298.15, 13.30,
                         3600.0) is None


def test_the_core_refuses_an_unknown_end_event():
    with pytest.raises(ValueError, match="end_event"):
        PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml"), end_event="median"))


def test_the_core_with_sampled_end_events_says_the_load_was_resampled():
    core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml"), end_event="sampled"))
    for k in range(400):  # 33 min of 5 s windows, a heavy one every minute
        core.update_state(WINDOW_S * k, 15.4, 4.0 if k % 12 == 0 else 1.5, 298.15)
    status = core.remaining_runtime(WINDOW_S * 399)
    assert status.valid and "resampled" in status.reason


def test_between_refreshes_the_core_keeps_the_sampled_answers_place_between_the_crossings(monkeypatch):
    import battery_predictor.prediction.runtime as runtime_mod
    from battery_predictor.prediction.core import SAMPLED_REFRESH_S

    calls = []
    real = runtime_mod.sampled_end_s

    def counted(*args, **kwargs):
        calls.append(args[-1])
        return real(*args, **kwargs)

    monkeypatch.setattr(runtime_mod, "sampled_end_s", counted)
    core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml"), end_event="sampled"))
    answers = []
    for k in range(600):  # 50 min of 5 s windows, a heavy one every minute; an answer every 10 s after 30 min
        core.update_state(WINDOW_S * k, 15.4 - 0.0004 * k, 4.0 if k % 12 == 0 else 1.5, 298.15)
        if k >= 360 and k % 2 == 0:
            answers.append(core.remaining_runtime(WINDOW_S * k))
    assert all(a.valid and "resampled" in a.reason for a in answers)
    span_s = WINDOW_S * (599 - 360)
    assert len(calls) == int(span_s // SAMPLED_REFRESH_S) + 1  # the futures ran once per refresh, not per answer


def _auto_answer(current_of_window, window_s=WINDOW_S):
    core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml")))
    assert core.config.end_event == "auto"
    n = int(2000 / window_s)  # 33 min of windows
    for k in range(n):
        core.update_state(window_s * k, 15.4, current_of_window(k), 298.15)
    return core.remaining_runtime(window_s * (n - 1))


def test_auto_end_event_resamples_a_load_whose_heavy_states_last_minutes():
    status = _auto_answer(lambda k: 3.0 if (k // 24) % 5 == 0 else 1.2)  # 2 min at 3 A every 10 min
    assert status.valid and "resampled" in status.reason, status.reason


def test_auto_end_event_keeps_the_peak_crossing_for_one_window_spikes():
    status = _auto_answer(lambda k: 4.0 if k % 12 == 0 else 1.5)  # a heavy 5 s window every minute
    assert status.valid and "A peaks" in status.reason and "resampled" not in status.reason, status.reason


def test_auto_end_event_asks_for_three_windows_per_heavy_state_whatever_the_window_length():
    status = _auto_answer(lambda k: 4.0 if k % 4 == 0 else 1.5, window_s=30.0)  # one heavy 30 s window in four
    assert status.valid and "A peaks" in status.reason and "resampled" not in status.reason, status.reason
