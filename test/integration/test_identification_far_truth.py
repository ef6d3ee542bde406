"""Identification from far away: a Temi or Ranger truth drawn far from the shipped params, a held-out day.

The generator (``benchmarks/identification_far_truth.py``) draws every identifiable coordinate
in its physical range, simulates a lumped-thermal pack recorded as the paper's instruments record
(10 Hz readings with noise and quantisation, averaged over 5 s), fits
one day (on the SPM engine) and predicts another. More draws: ``BP_FAR_TRUTH_SEEDS="0 1 2" pytest ...``.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from battery_predictor.params import load_params

REPO = Path(__file__).resolve().parents[2]
SEEDS = [int(s) for s in os.environ.get("BP_FAR_TRUTH_SEEDS", "0").split()]


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("pack", ["temi", "ranger"])
def test_a_far_truth_is_fitted_to_the_noise_and_its_held_out_runtime_within_one_percent(pack, seed, repo_script):
    gen = repo_script("benchmarks/identification_far_truth.py")
    params = load_params(REPO / "params" / gen.PACKS[pack][0])
    out = gen.run_seed(params, seed, evaluations=gen.DEFAULT_EVALUATIONS, resample_s=None, simulator="engine", pack=pack)  # as `fit` prepares the 5 s day
    # the paper's instruments: 10 Hz readings with 5 mV noise and 10 mV / 0.1 A resolution, averaged over 5 s
    assert out["fit_rmse_mv"] < 2 * gen.NOISE_V * 1e3
    assert abs(out["heldout_runtime_error_vs_noise_free_pct"]) < 1.0
    assert all(out["determined"].values())
    # the held-out day within twice the sensor's noise (issue 17)
    assert out["heldout_rmse_to_threshold_mv"] < 2 * gen.NOISE_V * 1e3
