"""Every fit path keeps the fit data's deepest state and the weak group their stop implies (fitting.data_limits)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import SimulationError
from battery_predictor.fitting import data_limits
from battery_predictor.fitting.data_limits import with_fit_data_limits
from battery_predictor.params import load_params
from battery_predictor.recording import DEEPEST_STATE_KEYS, Recording
from battery_predictor.simulation.extensions import weak_group_fraction

PARAMS = Path(__file__).resolve().parents[2] / "params"


def ranger():
    return load_params(PARAMS / "ranger_mini.yaml")


def stopped_on_the_plateau() -> Recording:
    """An hour on a falling plateau (49 -> 47.5 V at 2 A), switched off under load above the 46.31 V threshold."""
    t = np.arange(0.0, 3600.0, 60.0)
    return Recording(t, np.linspace(49.0, 47.5, t.size), np.full(t.size, 2.0))


def test_fit_data_that_stop_on_the_plateau_give_the_params_their_deepest_state_and_a_weak_group():
    limits = with_fit_data_limits(ranger(), [stopped_on_the_plateau()])
    assert limits.deepest is not None
    assert limits.deepest.voltage_v == pytest.approx(47.5)
    assert set(DEEPEST_STATE_KEYS) <= set(limits.params.thresholds)
    assert "cell_imbalance" in limits.params.extensions
    assert weak_group_fraction(limits.params) < 1.0
    assert limits.weak_group_line.startswith("weak series group inferred")


def test_without_the_inference_the_deepest_state_is_kept_and_the_cells_stay_identical():
    limits = with_fit_data_limits(ranger(), [stopped_on_the_plateau()], infer_weak_group=False)
    assert set(DEEPEST_STATE_KEYS) <= set(limits.params.thresholds)
    assert "cell_imbalance" not in limits.params.extensions
    assert limits.weak_group_line == "no weak series group inferred (--no-weak-group-inference)"


def test_a_model_failure_of_the_inference_keeps_the_fit_and_says_so(monkeypatch):
    def fails(*_args, **_kwargs):
        raise SimulationError("solver gave up")

    monkeypatch.setattr(data_limits, "inferred_weak_fraction", fails)
    limits = with_fit_data_limits(ranger(), [stopped_on_the_plateau()])
    assert limits.deepest is not None
    assert "cell_imbalance" not in limits.params.extensions
    assert limits.weak_group_line == "no weak series group inferred (the model failed: solver gave up)"
