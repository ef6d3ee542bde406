"""The error split of benchmarks/runtime_error_split.py recovers what made a model's own discharge."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.evaluation.runtime_eval import Windows
from battery_predictor.params import load_params
from battery_predictor.prediction.pack_model import engine_pack
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[2]
PARAMS = REPO / "params" / "panasonic_18650pf.yaml"
START_SOC = 0.83


@pytest.fixture(scope="module")
def split(repo_script):
    return repo_script("benchmarks/runtime_error_split.py")


@pytest.fixture(scope="module")
def own_discharge() -> Recording:
    """The params' model from SOC 0.83 under 2 A / 4 A steps of 60 s to 2.5 V, sampled every second at 25 degC."""
    runner = engine_pack(load_params(PARAMS))
    steps = [(60.0, 2.0 if k % 2 == 0 else 4.0) for k in range(200)]
    run = runner.run(START_SOC, steps, 298.15)
    assert run.reached_cutoff
    t = np.arange(0.0, run.end_time_s, 1.0)
    v = np.interp(t, run.time_s, run.pack_voltage_v)
    i = np.array([2.0 if int(x // 60) % 2 == 0 else 4.0 for x in t])
    return Recording(t, v, i, np.full(t.size, 298.15), source="own_discharge")


def test_the_consistent_start_soc_is_the_one_that_made_the_discharge(split, own_discharge):
    params = load_params(PARAMS)
    win = Windows.of(own_discharge)
    runner = engine_pack(params)
    soc = split.consistent_start_soc(runner, win, 0.0, float(own_discharge.time_s[-1]), 2.5)
    assert soc == pytest.approx(START_SOC, abs=0.01)


def test_a_start_no_soc_can_explain_is_nan_not_a_bound(split, own_discharge):
    win = Windows.of(own_discharge)
    runner = engine_pack(load_params(PARAMS))
    # a discharge ten times longer than the full model can run
    assert math.isnan(split.consistent_start_soc(runner, win, 0.0, 10 * float(own_discharge.time_s[-1]), 2.5))


def test_the_load_known_answers_and_the_predictors_are_scored_alike(split, own_discharge):
    res = split.split_recording(load_params(PARAMS), own_discharge, 2.5)
    rows = res["rows"]
    assert [r["fraction"] for r in rows] == pytest.approx([0.1 * k for k in range(1, 10)])
    for key in ("predictor_min", "load_known_min"):
        f = split.figures(rows, key)
        assert f["mae_min"] < 0.1 * rows[0]["true_min"]  # its own model: both close to the truth
        assert f["over_half_after_30pct"] == 0
    assert res["consistent_start_soc"] == pytest.approx(START_SOC, abs=0.01)
