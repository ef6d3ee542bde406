"""The padding past a recording's end: the load that took the cell to its cut-off continues."""

from __future__ import annotations

import numpy as np
import pytest

from battery_predictor.errors import ProfileError
from battery_predictor.fitting.problem import END_LOAD_WINDOW_S, end_current_a
from battery_predictor.simulation import StepLoad


def test_mean_current_over_the_last_seconds_weights_each_step_by_its_time_inside_the_window():
    load = StepLoad.from_durations([100.0, 30.0, 20.0], [0.0, 1.0, 4.0])
    assert load.mean_current_a(40.0) == pytest.approx((20 * 1.0 + 20 * 4.0) / 40.0)
    assert load.mean_current_a(1000.0) == pytest.approx(load.mean_current_a())
    assert load.mean_current_a() == pytest.approx((30 * 1.0 + 20 * 4.0) / 150.0)
    with pytest.raises(ProfileError, match="window"):
        load.mean_current_a(0.0)


def test_a_recording_mostly_at_rest_that_ends_in_a_load_step_is_continued_at_that_step():
    # an HPPC-like recording: long rests, the cut-off reached in a 3 A step
    load = StepLoad.from_durations([3000.0, 10.0, 3000.0, 2.0 * END_LOAD_WINDOW_S], [0.0, 3.0, 0.0, 3.0])
    assert load.mean_current_a() < 0.2
    assert end_current_a(load) == pytest.approx(3.0)


def test_a_tail_of_rest_or_regeneration_never_lowers_the_padding_below_the_recording_mean():
    load = StepLoad.from_durations([1000.0, END_LOAD_WINDOW_S], [2.0, -1.0])
    assert end_current_a(load) == pytest.approx(load.mean_current_a())
    charging = StepLoad.from_durations([100.0], [-1.0])
    assert end_current_a(charging) == 0.0


def test_samples_hold_until_the_next_one_so_the_window_ends_one_interval_after_the_last_sample():
    t = np.arange(0.0, 200.0, 10.0)
    load = StepLoad.from_samples(t, np.where(t >= 150.0, 5.0, 0.5))
    assert end_current_a(load) == pytest.approx((5 * 10 * 5.0 + 10 * 0.5) / 60.0)
