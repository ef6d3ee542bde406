"""The diagnosis claims no effect from errors that arise only where the observed day goes deeper than the references."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.diagnosis.candidates import CANDIDATES
from battery_predictor.diagnosis.coverage import reference_coverage
from battery_predictor.diagnosis.diagnose import _decide
from battery_predictor.diagnosis.engine import Engine, SimOut, observe, soc_from_voltage
from battery_predictor.diagnosis.reference import ReferenceFit
from battery_predictor.diagnosis.residuals import pack_capacity_ah
from battery_predictor.diagnosis.results import CandidateResult
from battery_predictor.diagnosis.scoring import held_out_score, pooled
from battery_predictor.params import load_params
from battery_predictor.recording import Recording

PARAMS = Path(__file__).resolve().parents[2] / "params"
START_OCV_V = 4.05  # per cell, both days
NOISE_V = 0.003
DT_S = 10.0
HOURS = 5.0


@pytest.fixture(scope="module")
def setup():
    params = load_params(PARAMS / "temi.yaml")
    engine = Engine()
    soc0 = soc_from_voltage(engine, params, START_OCV_V)
    capacity = pack_capacity_ah(engine, params)
    return params, engine, soc0, capacity


def _day(params, capacity_ah: float, drawn_fraction: float, seed: int, temperature_k: float | None = None):
    """A constant-current day drawing ``drawn_fraction`` of the model's capacity; a smooth voltage plus noise."""
    t = np.arange(0.0, HOURS * 3600.0 + DT_S, DT_S)
    current = drawn_fraction * capacity_ah / HOURS
    depth = t / t[-1] * drawn_fraction  # SOC drawn so far
    v_true = params.series * (START_OCV_V - 0.6 * depth)
    rng = np.random.default_rng(seed)
    v = v_true + rng.normal(0.0, NOISE_V, t.size)
    temp = None if temperature_k is None else np.full(t.size, temperature_k)
    return Recording(t, v, np.full(t.size, current), temp), v_true, depth


def _result(cause: str, obs, sim: SimOut, soc0: float, base_rmse_mv: float | None = None) -> CandidateResult:
    agg = pooled([held_out_score(obs, sim)])
    res = CandidateResult(cause=cause, fitted={}, socs=[soc0], heldout_rmse_mV=agg["heldout_rmse_mV"],
                          heldout_r2_mod=agg["heldout_r2_mod"], runtime_error_s=agg["runtime_error_s"],
                          fit_rmse_mV=0.0, evaluations=0, failures=0, seconds=0.0, sims=[sim])
    if base_rmse_mv is not None:
        res.gain_pct = 100.0 * (base_rmse_mv - res.heldout_rmse_mV) / base_rmse_mv
    return res


def _sim(t: np.ndarray, v: np.ndarray) -> SimOut:
    return SimOut(t=t, v_pack=v, v_cell_min=v / 4.0, reached_cutoff=False, end_time_s=float(t[-1]))


def _diagnose(setup, error_from_depth: float, end_padding: bool = False, cause: str = "capacity_fade",
              observed_k: float | None = None, fitted: dict[str, float] | None = None):
    """Reference day draws 45 % of the capacity, observed day 65 %; the baseline's error grows from ``error_from_depth``.

    The candidate ``cause`` predicts the observed day exactly (within the noise). ``observed_k``: the
    observed day's measured temperature (K; the reference's is 298.15 K), else none is measured.
    """
    params, engine, soc0, capacity = setup
    ref_rec, _, _ = _day(params, capacity, 0.45, seed=1, temperature_k=None if observed_k is None else 298.15)
    obs_rec, v_true, depth = _day(params, capacity, 0.65, seed=2, temperature_k=observed_k)
    ref = observe(ref_rec, params, fit_fraction=0.95)
    if end_padding:
        ref = replace(ref, ends_at_cutoff=True)
    obs = observe(obs_rec, params, fit_fraction=0.6)
    # a knee-like error of the baseline: zero before ``error_from_depth``, 0.25 V per cell at the end
    over = np.clip((depth - error_from_depth) / (0.65 - error_from_depth), 0.0, None)
    base_v = v_true + params.series * 0.25 * over ** 2
    base = _result("none", obs, _sim(obs.t, base_v), soc0)
    best = _result(cause, obs, _sim(obs.t, v_true.copy()), soc0, base.heldout_rmse_mV)
    best.fitted = dict(fitted or {})
    reference = ReferenceFit(values={}, socs=[START_OCV_V], rmse_mV=4.0, initial_rmse_mV=50.0, evaluations=0,
                             skipped=[], seconds=0.0, end_padding=end_padding)
    run = dict(seconds=0.0, budget=2, fit_fraction=0.6, split="time")
    return _decide(engine, params, [obs], [ref], reference, base, [best], run)


def _reference_and_observed_days(setup):
    """A reference day drawing 45 % of the capacity, an observed one reading 65 %, and the reference fit."""
    params, engine, soc0, capacity = setup
    ref = observe(_day(params, capacity, 0.45, 1)[0], params, fit_fraction=0.95)
    obs = observe(_day(params, capacity, 0.65, 2)[0], params, fit_fraction=0.6)
    reference = ReferenceFit(values={}, socs=[START_OCV_V], rmse_mV=4.0, initial_rmse_mV=50.0, evaluations=0,
                             skipped=[], seconds=0.0)
    return ref, obs, reference


def test_coverage_is_the_charge_the_references_drew(setup):
    params, engine, soc0, capacity = setup
    ref, obs, reference = _reference_and_observed_days(setup)
    cov = reference_coverage([ref], reference, [obs])
    assert cov.reference_drawn_ah == pytest.approx(0.45 * capacity, rel=1e-3)
    assert cov.covered_until_s[0] == pytest.approx(0.45 / 0.65 * HOURS * 3600.0, abs=2 * DT_S)
    assert 0 < cov.covered_heldout_samples < cov.heldout_samples
    # a shallower observed day never leaves the references' range
    shallow = observe(_day(params, capacity, 0.40, 3)[0], params, fit_fraction=0.6)
    assert not reference_coverage([ref], reference, [shallow]).leaves_range


def test_no_claim_from_an_error_only_deeper_than_the_references(setup):
    # the baseline errs only beyond 50 % drawn (references: 45 %): the error of an extrapolated knee
    diag = _diagnose(setup, error_from_depth=0.5)
    assert diag.baseline.heldout_rmse_mV > 50.0  # the whole held-out part would name capacity fade
    assert diag.coverage is not None and diag.coverage.refused
    assert diag.cause == "none" and diag.gain_pct == 0.0
    assert "deeper than the reference recordings" in diag.evidence
    assert diag.to_json()["reference_coverage"]["refused"] is True


def test_an_effect_that_shows_within_the_references_depth_is_still_named(setup):
    # capacity fade: the knee comes forward, the error starts at 25 % drawn, inside the covered range
    diag = _diagnose(setup, error_from_depth=0.25)
    assert diag.coverage is not None and diag.coverage.leaves_range and not diag.coverage.refused
    assert diag.cause == "capacity_fade" and diag.gain_pct > 50.0


def test_a_reference_that_stopped_at_its_cutoff_covers_every_depth(setup):
    diag = _diagnose(setup, error_from_depth=0.5, end_padding=True)
    assert diag.coverage is not None and not diag.coverage.leaves_range
    assert diag.cause == "capacity_fade"


def test_a_measured_temperature_change_is_named_with_a_caveat(setup):
    # the same deep-only error, but the observed day is measured 20 K colder than the reference: the
    # change is measured, so temperature is named; the caveat gives its gain within the references' depth
    diag = _diagnose(setup, error_from_depth=0.5, cause="temperature", observed_k=278.15)
    assert diag.cause == "temperature" and diag.coverage is not None and diag.coverage.measured
    assert "Caveat: the observed data go deeper" in diag.evidence
    # without a measured shift the same candidate is refused like any hidden cause
    same_k = _diagnose(setup, error_from_depth=0.5, cause="temperature", observed_k=298.15)
    assert same_k.cause == "none" and same_k.coverage is not None and same_k.coverage.refused


def test_a_current_offset_is_taken_off_the_reading_before_the_depth_is_measured(setup):
    # the observed day reads 0.65 of the capacity but 0.25 of it is the sensor's offset: the cells drew 0.40
    capacity = setup[3]
    ref, obs, reference = _reference_and_observed_days(setup)
    offset_a = 0.25 * capacity / HOURS
    read = reference_coverage([ref], reference, [obs])
    drawn = reference_coverage([ref], reference, [obs], offset_a)
    assert read.leaves_range and not drawn.leaves_range
    assert drawn.observed_drawn_ah[0] == pytest.approx(0.40 * capacity, rel=1e-3)
    assert drawn.to_json()["sensor_offset_a"] == pytest.approx(offset_a)


def test_a_named_current_offset_is_judged_at_the_depth_it_implies(setup):
    # the same error beyond the references' depth, but the cause says the reading is 0.25 C-h too high
    params, engine, soc0, capacity = setup
    offset_a = 0.25 * capacity / HOURS
    diag = _diagnose(setup, error_from_depth=0.5, cause="current_offset", fitted={"current_offset_a": offset_a})
    assert diag.cause == "current_offset" and not diag.coverage.leaves_range
    assert _diagnose(setup, error_from_depth=0.5, cause="current_offset").cause == "none"


def test_only_the_current_offset_cause_says_the_reading_is_biased():
    fitted = {"current_offset_a": 0.3, "weak_group_capacity_fraction": 0.9}
    offsets = {c.name: c.sensor_offset_a(fitted) for c in CANDIDATES}
    assert offsets.pop("current_offset") == 0.3
    assert set(offsets.values()) == {0.0}
