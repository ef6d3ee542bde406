"""Diagnosis hold-out: the cross-recording folds (several observed recordings) and the cold-data caveat."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.diagnosis.diagnose import combine_folds, diagnose, fold_observed
from battery_predictor.diagnosis.engine import Engine, SimOut, observe
from battery_predictor.diagnosis.residuals import ResidualAnalysis, evidence_text
from battery_predictor.diagnosis.results import CandidateResult
from battery_predictor.diagnosis.scoring import held_out_score
from battery_predictor.errors import BatteryPredictorError
from battery_predictor.params import load_params
from battery_predictor.recording import Recording

PARAMS = Path(__file__).resolve().parents[2] / "params"


def _discharge(n: int = 100, v_end: float = 3.0) -> Recording:
    t = np.arange(float(n))
    return Recording(t, np.linspace(4.0, v_end, n), np.ones(n), np.full(n, 283.15))


def test_fold_keeps_the_time_split_of_the_held_out_recording_only():
    params = load_params(PARAMS / "lgm50.yaml")
    obs = [observe(_discharge(n), params, fit_fraction=0.6) for n in (100, 200, 300)]
    fold = fold_observed(obs, 1)
    assert fold[1] is obs[1] and fold[1].held_mask.sum() > 0
    for k in (0, 2):  # the other recordings are fitted whole
        assert fold[k].fit_mask.all() and not fold[k].held_mask.any()
        assert fold[k].load is obs[k].load


def test_combine_folds_scores_each_recording_by_the_fold_that_held_it_out():
    params = load_params(PARAMS / "lgm50.yaml")
    obs = [observe(_discharge(100), params, fit_fraction=0.5), observe(_discharge(100), params, fit_fraction=0.5)]
    exact = SimOut(
        t=obs[0].t, v_pack=obs[0].v.copy(), v_cell_min=obs[0].v.copy(), reached_cutoff=False, end_time_s=99.0
    )
    off = SimOut(t=obs[1].t, v_pack=obs[1].v + 0.01, v_cell_min=obs[1].v + 0.01, reached_cutoff=False, end_time_s=99.0)
    folds = [
        {
            "theta": {"x": 1.0},
            "soc": 0.9,
            "sim": exact,
            "score": held_out_score(obs[0], exact),
            "fit_rmse_mV": 2.0,
            "evaluations": 10,
            "failures": 0,
            "seconds": 1.0,
        },
        {
            "theta": {"x": 3.0},
            "soc": 0.8,
            "sim": off,
            "score": held_out_score(obs[1], off),
            "fit_rmse_mV": 4.0,
            "evaluations": 12,
            "failures": 1,
            "seconds": 2.0,
        },
    ]
    res = combine_folds("current_offset", obs, folds)
    n0, n1 = int(obs[0].held_mask.sum()), int(obs[1].held_mask.sum())
    assert res.heldout_rmse_mV == pytest.approx(10.0 * math.sqrt(n1 / (n0 + n1)), rel=1e-6)
    assert res.fitted == {"x": 2.0} and res.fitted_folds == [{"x": 1.0}, {"x": 3.0}]
    assert res.socs == [0.9, 0.8] and res.sims == [exact, off]
    assert res.evaluations == 22 and res.failures == 1
    assert "fitted_folds" in res.row()


def test_cross_recording_split_needs_two_recordings():
    params = load_params(PARAMS / "lgm50.yaml")
    with pytest.raises(BatteryPredictorError, match="at least two"):
        diagnose(params, [_discharge()], split="recordings")
    with pytest.raises(BatteryPredictorError, match="split"):
        diagnose(params, [_discharge()], split="folds")


def test_capacity_like_cause_on_colder_data_carries_a_caveat():
    def row(cause, rmse, gain):
        r = CandidateResult(cause, {}, [0.9], rmse, 0.9, None, 0.0, 0, 0, 0.0)
        r.gain_pct = gain
        return r

    base = row("none", 150.0, 0.0)
    offset, temp = row("current_offset", 90.0, 40.0), row("temperature", 155.0, -3.0)
    analysis = ResidualAnalysis({"time": 0.4}, {"time": -0.6}, 96.0, -10.0, [])
    cold = evidence_text("current_offset", base, offset, [offset, temp], analysis, 1.0, [], 25.0, -15.0)
    assert "Caveat" in cold and "15 K colder" in cold
    same = evidence_text("current_offset", base, offset, [offset, temp], analysis, 1.0, [], 25.0, -1.0)
    assert "Caveat" not in same
    temp.gain_pct, temp.heldout_rmse_mV = 45.0, 80.0
    physical = evidence_text("temperature", base, temp, [offset, temp], analysis, 1.0, [], 25.0, -15.0)
    assert "Caveat" not in physical
    assert "(voltage noise 1.0 mV)" in physical
    # window averages of a varying current: nothing to measure the noise on, which the text says
    unmeasured = evidence_text("temperature", base, temp, [offset, temp], analysis, 0.0, [], 25.0, -15.0)
    assert "voltage noise not measurable here" in unmeasured and "noise 0.0 mV" not in unmeasured


def test_auto_split_folds_few_recordings_and_falls_back_to_time_when_folds_get_expensive():
    from battery_predictor.diagnosis.diagnose import MAX_FOLD_STEPS, auto_split

    params = load_params(PARAMS / "lgm50.yaml")
    cc = [observe(_discharge(n), params, fit_fraction=0.6) for n in (100, 200, 300)]  # one current step each
    assert auto_split(cc) == "recordings"
    assert auto_split(cc[:1]) == "time"
    n = MAX_FOLD_STEPS // 2 + 2  # two recordings of n steps: 2 x 2n folds x steps > the limit
    rng = np.random.default_rng(0)
    drive = [Recording(np.arange(float(n)), np.full(n, 3.7), rng.uniform(0.5, 2.0, n), np.full(n, 283.15))
             for _ in range(2)]
    assert auto_split([observe(r, params, fit_fraction=0.6) for r in drive]) == "time"


def test_capacity_fade_fits_on_params_with_a_cold_window_share_one_engine_extraction():
    # the shipped Panasonic params carry an a-priori cold window; the window narrows towards the charged end's
    # stoichiometries, which a faded cell moves: fixed at the diagnosed params' own, every run is one extraction
    params = load_params(PARAMS / "panasonic_18650pf.yaml")
    n = 240
    t = 10.0 * np.arange(float(n))
    rec = Recording(t, np.linspace(4.05, 3.55, n), np.full(n, 1.5), np.full(n, 278.15))
    engine = Engine()
    result = diagnose(params, [rec], causes=["capacity_fade"], budget=8, workers=1, engine=engine)
    fade = next(c for c in result.candidates if c.cause == "capacity_fade")
    assert fade.evaluations >= 8
    assert engine._spm is not None and engine.engine_runs >= 16
    assert engine._spm.extractions == 1
