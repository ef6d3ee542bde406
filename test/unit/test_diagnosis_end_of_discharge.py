"""How the diagnosis handles the end of a discharge: the rest after it, a measured dip below the cut-off."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.diagnosis.engine import (
    CUTOFF_MARGIN_V,
    model_cutoff_v,
    observe,
    without_trailing_rest,
)
from battery_predictor.params import load_params
from battery_predictor.recording import Recording

PARAMS = Path(__file__).resolve().parents[2] / "params"


def _discharge_then(tail_current_a: float) -> Recording:
    t = np.arange(0.0, 1300.0, 10.0)
    i = np.where(t < 1000.0, 2.0, tail_current_a)
    v = np.where(t < 1000.0, np.linspace(4.1, 2.6, t.size), 3.3)
    return Recording(t, v, i, None)


def test_trailing_rest_after_the_last_discharge_is_dropped():
    trimmed = without_trailing_rest(_discharge_then(0.0))
    assert trimmed.time_s[-1] == pytest.approx(990.0)
    assert np.all(trimmed.current_a > 0)


def test_a_recharge_after_the_discharge_is_kept():
    rec = _discharge_then(-1.0)
    assert without_trailing_rest(rec).time_s.size == rec.time_s.size


def test_observe_scores_no_rest_after_the_end_of_discharge():
    params = load_params(PARAMS / "panasonic_18650pf.yaml")
    obs = observe(_discharge_then(0.0), params)
    assert obs.t[-1] == pytest.approx(990.0)
    assert obs.t_split < obs.t[-1]


def test_simulation_may_follow_a_measured_dip_below_the_cutoff():
    params = load_params(PARAMS / "panasonic_18650pf.yaml")
    t = np.arange(0.0, 200.0, 10.0)
    dip = Recording(t, np.linspace(3.6, 2.45, t.size), np.full(t.size, 2.0), None)
    high = Recording(t, np.linspace(3.9, 3.5, t.size), np.full(t.size, 2.0), None)
    assert model_cutoff_v(2.5, observe(dip, params), 1) == pytest.approx(2.45 - CUTOFF_MARGIN_V)
    assert model_cutoff_v(2.5, observe(high, params), 1) == pytest.approx(2.5)
