"""R2_mod of the seed paper, Eq. (1)-(3), against values computed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from battery_predictor.fitting.cost import align_for_r2_mod, r2_mod, rmse_v


def test_identical_curves_score_one():
    t = np.arange(5.0)
    u = np.array([4.0, 3.9, 3.8, 3.7, 3.6])
    assert r2_mod(t, u, t, u) == pytest.approx(1.0)


def test_hand_computed_value_on_same_grid():
    # measured 4,3,2 (mean 3, SS_tot = 2); prediction 4,3.5,2 -> SS_res = 0.25 -> R2 = 0.875
    t = np.array([0.0, 1.0, 2.0])
    assert r2_mod(t, [4.0, 3.0, 2.0], t, [4.0, 3.5, 2.0]) == pytest.approx(0.875)


def test_prediction_interpolated_onto_measurement_grid():
    # prediction at t=0,2 (4 -> 2) interpolates to 3 at t=1: perfect on 4,3,2
    assert r2_mod([0.0, 1.0, 2.0], [4.0, 3.0, 2.0], [0.0, 2.0], [4.0, 2.0]) == pytest.approx(1.0)


def test_prediction_ending_early_is_padded_with_u_min():
    # measured 4,3,2 at t=0,1,2; prediction ends at t=1 (4,3) -> padded U_min=2 at t=2: perfect
    assert r2_mod([0, 1, 2], [4.0, 3.0, 2.0], [0.0, 1.0], [4.0, 3.0]) == pytest.approx(1.0)
    # prediction ends at t=0 with 4 -> t=1 padded 2 (error 1), t=2 padded 2 -> SS_res=1, SS_tot=2 -> 0.5
    assert r2_mod([0, 1, 2], [4.0, 3.0, 2.0], [0.0], [4.0]) == pytest.approx(0.5)


def test_prediction_below_u_min_is_truncated():
    # prediction dips below U_min=2 at t=1: truncated after t=0 -> same as the previous case
    assert r2_mod([0, 1, 2], [4.0, 3.0, 2.0], [0.0, 1.0, 2.0], [4.0, 1.5, 3.0]) == pytest.approx(0.5)


def test_prediction_ending_late_extends_measurement_with_u_min():
    # measured 4,3,2 at t=0,1,2 (dt=1); prediction 4,3,3,3 until t=3.
    # extended grid t=0..3, measured 4,3,2,2 (mean 2.75, SS_tot = 1.5625+0.0625+0.5625+0.5625 = 2.75)
    # prediction 4,3,3,3 -> SS_res = 0 + 0 + 1 + 1 = 2 -> R2 = 1 - 2/2.75
    a = align_for_r2_mod([0, 1, 2], [4.0, 3.0, 2.0], [0, 1, 2, 3], [4.0, 3.0, 3.0, 3.0])
    np.testing.assert_allclose(a.time_s, [0, 1, 2, 3])
    np.testing.assert_allclose(a.measured_v, [4, 3, 2, 2])
    assert r2_mod([0, 1, 2], [4.0, 3.0, 2.0], [0, 1, 2, 3], [4.0, 3.0, 3.0, 3.0]) == pytest.approx(1 - 2 / 2.75)


def test_a_recording_that_stops_above_its_cutoff_is_neither_truncated_nor_extended():
    # a working day that stopped at 3 V (not its cut-off): the prediction's dip to 1.5 V at t=1 is an error
    # of 1.5 V there, not the end of the prediction; its continuation past t=2 is not compared
    t, u = [0.0, 1.0, 2.0], [4.0, 3.0, 2.0]
    assert r2_mod(t, u, [0.0, 1.0, 2.0, 3.0], [4.0, 1.5, 2.0, 3.0], ends_at_cutoff=False) == pytest.approx(1 - 2.25 / 2)
    a = align_for_r2_mod(t, u, [0, 1, 2, 3], [4.0, 3.0, 3.0, 3.0], ends_at_cutoff=False)
    np.testing.assert_allclose(a.time_s, t)
    # a prediction that ends early is still padded with U_min (the model stopped before the data did)
    assert r2_mod(t, u, [0.0], [4.0], ends_at_cutoff=False) == pytest.approx(0.5)


def test_empty_prediction_is_all_u_min():
    # padded 2,2,2 against 4,3,2: SS_res = 4+1+0 = 5, SS_tot = 2 -> -1.5
    assert r2_mod([0, 1, 2], [4.0, 3.0, 2.0], [], []) == pytest.approx(-1.5)


def test_rmse_over_overlap_only():
    assert rmse_v([0, 1, 2], [4.0, 3.0, 2.0], [0, 1], [4.0, 2.0]) == pytest.approx(np.sqrt(0.5))
